"""Reference vs model deformed shapes, magnified, one panel per load case (Deussen Fig.
8-11): the springs at rest (grey), the model's deformed network (blue) and the reference
displacement of the same nodes (red dots). 3-D networks are projected on x-y. One PNG
per ``deformed*.npz`` file (one per model)."""

from __future__ import annotations

import math
from pathlib import Path

from harness.figures import save, subplots

NAME, SCOPE = "deformed", "case"


def _lines(ax, p, springs, **kw):
    from matplotlib.collections import LineCollection
    ax.add_collection(LineCollection(p[springs][:, :, :2], **kw))


def make(folder: Path) -> list[Path]:
    return [p for p in (_one(src, folder) for src in sorted(folder.glob("deformed*.npz"))) if p]


def _one(src: Path, folder: Path) -> Path | None:
    import numpy as np
    suffix = src.stem[len("deformed"):]
    with np.load(src) as z:
        data = {k: z[k] for k in z.files}
    p = np.asarray(data["points"], float)
    springs = np.asarray(data["springs"], int) if "springs" in data else None
    keep = np.ones(len(p), bool)
    if p.shape[1] == 3:  # 3-D: draw the top face z = max (a projection of everything is unreadable)
        z = p[:, 2]
        keep = np.abs(z - z.max()) <= 1e-9 * (np.ptp(p, axis=0).max() or 1.0)
        if springs is not None:
            springs = springs[keep[springs].all(axis=1)]
    loads = sorted(k[len("u_ref_"):] for k in data if k.startswith("u_ref_"))
    if not loads:
        return None
    size = float(np.ptp(p, axis=0).max()) or 1.0
    us = {l: (np.asarray(data[f"u_ref_{l}"], float),
              np.asarray(data.get(f"u_{l}", np.full_like(data[f"u_ref_{l}"], np.nan)), float)) for l in loads}
    umax = max(float(np.nanmax(np.abs(np.concatenate(u)))) for u in us.values())
    scale = float(data["scale"]) if "scale" in data else (0.1 * size / umax if umax > 0 else 1.0)
    cols = min(len(loads), 3 if len(loads) > 4 else 2 if len(loads) > 1 else 1)
    rows = math.ceil(len(loads) / cols)
    fig, axes = subplots(rows, cols, figsize=(3.4 * cols, 3.4 * rows), squeeze=False)
    for ax, load in zip(axes.ravel(), loads):
        u_ref, u = us[load]
        if springs is not None and len(springs):
            _lines(ax, p, springs, colors="0.8", linewidths=0.5)
            if np.isfinite(u).all():
                _lines(ax, p + scale * u, springs, colors="tab:blue", linewidths=0.8)
        elif np.isfinite(u).all():
            ax.plot(*(p + scale * u)[keep, :2].T, "o", color="tab:blue", ms=2)
        ax.plot(*(p + scale * u_ref)[keep, :2].T, ".", color="tab:red", ms=3)
        ax.set_aspect("equal")
        ax.autoscale()
        ax.set_title(load, fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(loads):]:
        ax.set_visible(False)
    top = ", top face z = max" if p.shape[1] == 3 else ""
    fig.suptitle(f"{folder.name}{suffix}: model (blue) vs FEM (red), x{scale:.3g}{top}", fontsize=9)
    fig.subplots_adjust(left=0.08, right=0.97, bottom=0.06, top=0.9, wspace=0.25, hspace=0.3)
    return save(fig, folder / f"fig-deformed{suffix}.png", tight=False)
