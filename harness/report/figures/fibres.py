"""Fibre field of a body (Bourguignon-Cani Fig. 6): fibre directions at element centres,
drawn as short segments in 3-D, at the deformed centres if ``u`` is stored."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.report.figures import LENGTH_UNIT, pyplot, save, title

NAME, SCOPE = "fibres", "case"
DATA = ("fibres*.npz",)  # the files it reads (globs in the folder): its figures' stamp


def make(folder: Path) -> list[Path]:
    return [_one(src, folder) for src in sorted(folder.glob("fibres*.npz"))]


def _one(src: Path, folder: Path) -> Path:
    suffix = src.stem[len("fibres") :]
    with np.load(src) as z:
        p = np.asarray(z["points"], float)
        d = np.asarray(z["directions"], float)
        u = np.asarray(z["u"], float) if "u" in z.files else np.zeros_like(p)
        names = set(z.files)
    if p.shape[1] == 2:
        p, d, u = (np.c_[a, np.zeros(len(a))] for a in (p, d, u))
    c = p + u
    size = float(np.ptp(p, axis=0).max()) or 1.0
    L = 0.3 * size / max(len(p), 1) ** (1 / 3)
    plt = pyplot()
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection="3d")
    for a, b in zip(c - 0.5 * L * d, c + 0.5 * L * d):
        ax.plot(*zip(a, b), color="tab:brown", lw=1)
    ax.set_box_aspect(np.maximum(np.ptp(c, axis=0), 1e-3 * size))
    for axis in "xyz":
        getattr(ax, f"set_{axis}label")(f"{axis} ({LENGTH_UNIT})")
    where = "deformed element centres" if "u" in names else "element centres"
    ax.set_title(f"{title(folder)}{suffix}: fibre directions at the {where}", fontsize=10)
    return save(fig, folder / f"fig-fibres{suffix}.png")
