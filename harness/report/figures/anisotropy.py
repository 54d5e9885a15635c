"""Polar plot of the effective stiffness against pull direction, one curve per model:
a perfectly isotropic model is a circle (undesired anisotropy, Bourguignon-Cani Fig. 1a/5a).
anisotropy.csv rows: angle (degrees in the x-y plane), model, stiffness, drift; a uniaxial
pull along d and along -d is the same load, so angles below 180 are drawn mirrored. The
FEM reference (model "FEM") is drawn dashed: the material's own anisotropy. The radius is
E_d in Pa (case files are SI), from 0."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.report.figures import read_csv, save, subplots, title

NAME, SCOPE = "anisotropy", "case"
DATA = ("anisotropy.csv",)  # the files it reads (globs in the folder): its figures' stamp


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "anisotropy.csv")
    if df is None or df.empty:
        return []
    fig, ax = subplots(figsize=(9, 6), subplot_kw={"projection": "polar"})
    groups = df.groupby("model", sort=True) if "model" in df else [("model", df)]
    for model, g in groups:
        g = g.sort_values("angle")
        a, k = g["angle"].to_numpy(float), g["stiffness"].to_numpy(float)
        if a.max() < 180:  # the same pull at angle + 180
            a, k = np.append(a, a + 180), np.append(k, k)
        th = np.deg2rad(a)
        style = "k--" if str(model) == "FEM" else "o-"
        ax.plot(np.append(th, th[:1]), np.append(k, k[:1]), style, ms=3, label=str(model))
    ax.set_ylim(bottom=0)
    ax.set_rlabel_position(112.5)  # between the 90 and 135 degree spokes
    from matplotlib.ticker import FuncFormatter

    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g} Pa"))
    ax.tick_params(axis="y", labelsize=8)
    ax.set_xlabel("pull direction in the x-y plane (degrees from x)", fontsize=9)
    ax.set_title(
        f"{title(folder)}: effective Young's modulus E_d against pull direction",
        fontsize=10,
        pad=18,
    )
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.08, 0.5))
    return [save(fig, folder / "fig-anisotropy.png")]
