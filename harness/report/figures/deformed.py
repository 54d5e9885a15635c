"""Reference vs model deformed shapes, magnified, one panel per load case (Deussen Fig.
8-11): the springs at rest (grey), the model's deformed network (blue) and the reference
displacement of the same nodes (red dots). A 3-D network is drawn in a 3-D view of the
body's surface facing the viewer (springs lying on a face of its convex hull: for a box
the front, side and top faces), so loads on every face show. One PNG per
``deformed*.npz`` file (one per model)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from harness.report.figures import LENGTH_UNIT, pyplot, save, title

NAME, SCOPE = "deformed", "case"
DATA = ("deformed*.npz",)  # the files it reads (globs in the folder): its figures' stamp
VIEW = (22.0, -58.0)  # elevation, azimuth (degrees) of the 3-D panels


def make(folder: Path) -> list[Path]:
    return [p for p in (_one(src, folder) for src in sorted(folder.glob("deformed*.npz"))) if p]


def visible_surface(p, springs, view=VIEW):
    """3-D: (nodes (n,) bool, springs (e,) bool) on the hull faces whose outward normal
    points towards the viewer; everything when the points span no volume."""
    from scipy.spatial import ConvexHull, QhullError

    n = len(p)
    try:
        eq = np.unique(np.round(ConvexHull(p).equations, 9), axis=0)  # coplanar facets: one plane
    except (QhullError, ValueError):
        return np.ones(n, bool), np.ones(len(springs) if springs is not None else 0, bool)
    el, az = np.deg2rad(view)
    eye = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    eq = eq[eq[:, :3] @ eye > 1e-9]
    tol = 1e-6 * (float(np.ptp(p, axis=0).max()) or 1.0)
    on = np.abs(p @ eq[:, :3].T + eq[:, 3]) <= tol  # (n, planes)
    keep = (
        (on[springs[:, 0]] & on[springs[:, 1]]).any(axis=1)
        if springs is not None
        else np.zeros(0, bool)
    )
    return on.any(axis=1), keep


def _one(src: Path, folder: Path) -> Path | None:
    suffix = src.stem[len("deformed") :]
    with np.load(src) as z:
        data = {k: z[k] for k in z.files}
    p = np.asarray(data["points"], float)
    springs = np.asarray(data["springs"], int) if "springs" in data else None
    dim = p.shape[1]
    keep = np.ones(len(p), bool)
    if dim == 3:
        keep, on = visible_surface(p, springs)
        if springs is not None:
            springs = springs[on]
    loads = sorted(k[len("u_ref_") :] for k in data if k.startswith("u_ref_"))
    if not loads:
        return None
    size = float(np.ptp(p, axis=0).max()) or 1.0
    us = {
        l: (
            np.asarray(data[f"u_ref_{l}"], float),
            np.asarray(data.get(f"u_{l}", np.full_like(data[f"u_ref_{l}"], np.nan)), float),
        )
        for l in loads
    }
    umax = max(float(np.nanmax(np.abs(np.concatenate(u)))) for u in us.values())
    # default magnification: the largest displacement at this part of the size
    frac = 0.2 if dim == 3 else 0.1
    scale = float(data["scale"]) if "scale" in data else (frac * size / umax if umax > 0 else 1.0)
    cols = min(len(loads), 3 if len(loads) > 4 else 2 if len(loads) > 1 else 1)
    rows = math.ceil(len(loads) / cols)
    fig = pyplot().figure(figsize=(3.6 * cols, (3.9 if dim == 3 else 3.5) * rows))
    # 3-D: drawn in call order
    kw = {"projection": "3d", "computed_zorder": False} if dim == 3 else {}
    for i, load in enumerate(loads):
        ax = fig.add_subplot(rows, cols, i + 1, **kw)
        u_ref, u = us[load]
        if springs is not None and len(springs):
            _lines(ax, p, springs, dim, colors="0.75", linewidths=0.5)
            if np.isfinite(u).all():
                _lines(ax, p + scale * u, springs, dim, colors="tab:blue", linewidths=0.9)
        elif np.isfinite(u).all():
            ax.plot(*(p + scale * u)[keep].T, "o", color="tab:blue", ms=2)
        ax.plot(*(p + scale * u_ref)[keep].T, ".", color="tab:red", ms=3)
        ax.set_title(load, fontsize=9)
        ax.tick_params(labelsize=6)
        if dim == 3:
            q = np.concatenate([p, p + scale * u_ref])[np.r_[keep, keep]]
            lo, hi = q.min(axis=0), q.max(axis=0)
            ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
            ax.set_box_aspect(np.maximum(hi - lo, 1e-3 * size))
            ax.view_init(*VIEW)
            ax.locator_params(nbins=4)
            for axis in "xyz":
                getattr(ax, f"set_{axis}label")(f"{axis} ({LENGTH_UNIT})", fontsize=7, labelpad=-4)
        else:
            ax.set_aspect("equal")
            ax.autoscale()
            ax.set_xlabel(f"x ({LENGTH_UNIT})", fontsize=7)
            ax.set_ylabel(f"y ({LENGTH_UNIT})", fontsize=7)
    view = ", surface facing the viewer" if dim == 3 else ""
    fig.suptitle(
        f"{title(folder)}{suffix}: model (blue) vs FEM (red dots), displacements "
        f"x{scale:.3g}{view}",
        fontsize=9,
    )
    fig.subplots_adjust(left=0.07, right=0.97, bottom=0.06, top=0.92, wspace=0.3, hspace=0.35)
    return save(fig, folder / f"fig-deformed{suffix}.png", tight=False)


def _lines(ax, p, springs, dim, colors, linewidths):
    seg = p[springs]
    # one polyline, the springs separated by NaN gaps (plain matplotlib, no mpl_toolkits)
    if dim == 3:
        gaps = np.concatenate([seg, np.full((len(seg), 1, 3), np.nan)], axis=1).reshape(-1, 3)
        ax.plot(gaps[:, 0], gaps[:, 1], gaps[:, 2], color=colors, linewidth=linewidths)
    else:
        from matplotlib.collections import LineCollection

        ax.add_collection(LineCollection(seg, colors=colors, linewidths=linewidths))
