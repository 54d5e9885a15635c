"""Polar plot of the effective stiffness against pull direction, one curve per model:
a perfectly isotropic model is a circle (undesired anisotropy, Bourguignon-Cani Fig. 1a/5a)."""

from __future__ import annotations

from pathlib import Path

from harness.figures import pyplot, save

NAME, SCOPE = "anisotropy", "case"


def make(folder: Path) -> list[Path]:
    src = folder / "anisotropy.csv"
    if not src.exists():
        return []
    import numpy as np
    import pandas as pd
    df = pd.read_csv(src)
    plt = pyplot()
    fig = plt.figure(figsize=(5, 5))
    ax = fig.add_subplot(projection="polar")
    groups = df.groupby("model", sort=True) if "model" in df else [("model", df)]
    for model, g in groups:
        g = g.sort_values("angle")
        th = np.deg2rad(g["angle"].to_numpy())
        k = g["stiffness"].to_numpy()
        ax.plot(np.append(th, th[:1]), np.append(k, k[:1]), "o-", ms=3, label=str(model))
    ax.set_title(f"{folder.name}: effective stiffness vs direction", fontsize=9)
    ax.legend(fontsize=8, loc="lower right")
    return [save(fig, folder / "fig-anisotropy.png")]
