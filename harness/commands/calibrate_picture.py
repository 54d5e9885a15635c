"""A picture of the fit, written beside MODEL.vtu: ``MODEL-heldout.vtu`` holds, per held-out
load, the FEM's and the model's displacement at the network's nodes, the error
|u_model - u_FEM| per node and the held (clamped) and loaded nodes as 0/1 point data (the
mesh's cells, so ParaView draws the body: warp by a displacement, colour by the error);
``MODEL-heldout.png`` draws the worst held-out load (the largest relative error, as the
JSON's ``G_heldout_loads``): the model's deformed shape, magnified, coloured by the error,
the regions marked. Users would rather look than read; the numbers are the scored ones
(:class:`harness.stages.sms.Heldout`), nothing is solved again."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from harness.io.meshfile import FACETS, boundary_facets
from harness.mechanics import statics
from harness.scoring import case_weights, g_arrays

SHOWN = 0.1  # the largest displacement drawn as this share of the body's largest extent
SOLIDS = {2: ("triangle", "quad"), 3: ("tetra", "hexahedron")}


def paths(out: Path) -> tuple[Path, Path]:
    """(MODEL-heldout.vtu, MODEL-heldout.png) beside ``out`` (MODEL.vtu)."""
    out = Path(out)
    return out.with_name(f"{out.stem}-heldout.vtu"), out.with_name(f"{out.stem}-heldout.png")


def regions(net, case, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(held, loaded) (n,) bool of load ``name`` on the network: the nodes with a component
    held at zero, and those the load's tractions push (the statics' own masks and forces;
    a body force alone, which acts on every node, marks none)."""
    load = next(l for l in case.loads if l.name == name)
    held = statics.fixed_mask(net.points, case, load).any(axis=1)
    surface = dataclasses.replace(
        load, gravity=None, body_force=None, stress=None, stress_gradient=None
    )
    loaded = np.any(statics.force_vector(net, case, surface) != 0, axis=1)
    return held, loaded


def _pad3(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    return np.pad(a, ((0, 0), (0, 3 - a.shape[1])))


def point_data(net, case, heldout) -> dict:
    """The VTU's point data, load by load in the case's order (module docstring)."""
    out = {}
    for name, fem, model in zip(heldout.names, heldout.u_fem, heldout.u_model):
        held, loaded = regions(net, case, name)
        out[f"u_fem/{name}"] = _pad3(fem)
        out[f"u_model/{name}"] = _pad3(model)
        out[f"error/{name}"] = np.linalg.norm(np.asarray(model) - np.asarray(fem), axis=1)
        out[f"held/{name}"] = held.astype(np.uint8)
        out[f"loaded/{name}"] = loaded.astype(np.uint8)
    return out


def _cells(net) -> list:
    """The network's solid cells (the body ParaView draws), else its springs as lines."""
    solid = [(t, np.asarray(c, np.int64)) for t, c in net.cells.items() if t in SOLIDS[net.dim]]
    return solid or [("line", np.asarray(net.springs, np.int64))]


def write_vtu(path: Path, net, data: dict) -> None:
    """MODEL-heldout.vtu (meshio; same input, same bytes)."""
    import meshio

    meshio.write(path, meshio.Mesh(_pad3(net.points), _cells(net), point_data=data), "vtu")


def worst(net, case, heldout) -> tuple[int, float]:
    """(index, relative error) of the held-out load with the largest normalised G (the
    scoring's per-load G_norm with the case's weights, the JSON's ``G_heldout_loads``)."""
    sc = g_arrays(heldout.u_fem, heldout.u_model, net.classes, case_weights(case), heldout.names)
    per = np.array([sc.per_load_norm[n] for n in heldout.names])
    at = int(np.nanargmax(per)) if np.isfinite(per).any() else 0
    return at, float(per[at])


def _triangles(net) -> np.ndarray | None:
    """(t, 3) triangles to draw: the boundary of a 3-D body, the cells of a 2-D one (quads
    split in two); None without cells (the nodes are drawn)."""
    cells = {t: c for t, c in net.cells.items() if t in SOLIDS[net.dim] and t in FACETS}
    if not cells:
        return None
    faces = boundary_facets(cells) if net.dim == 3 else list(cells.values())
    tris = [np.asarray(f)[:, [0, 1, 2]] for f in faces if np.shape(f)[1] in (3, 4)]
    tris += [np.asarray(f)[:, [0, 2, 3]] for f in faces if np.shape(f)[1] == 4]
    return np.concatenate(tris) if tris else None


def scale(points: np.ndarray, *u: np.ndarray) -> float:
    """The magnification that draws the largest displacement of ``u`` as SHOWN of the body's
    largest extent (two significant figures; 1 for a body that does not move)."""
    umax = max(float(np.linalg.norm(a, axis=1).max()) for a in u)
    size = float(np.ptp(points, axis=0).max())
    return float(f"{SHOWN * size / umax:.2g}") if umax > 0 else 1.0


def _mark(ax, x: np.ndarray, held: np.ndarray, loaded: np.ndarray, body_force: bool) -> None:
    """The held nodes (black squares) and the loaded ones (red triangles), with a legend."""
    for on, style, label in (
        (held, dict(c="k", marker="s"), "held (clamped)"),
        (loaded, dict(c="red", marker="^"), "loaded (traction)"),
    ):
        if on.any():
            ax.scatter(*x[on].T, s=14, label=label, zorder=5, **style)
    if body_force:
        ax.plot([], [], " ", label="body force on every node")
    ax.legend(loc="upper right" if x.shape[1] == 3 else "best", fontsize=8, framealpha=0.8)


def _body(fig, x: np.ndarray, tris, err: np.ndarray, norm, cmap):
    """The deformed body coloured by the error: a 3-D boundary surface (each facet its
    vertices' mean error), a 2-D Gouraud-shaded mesh, or the nodes alone; its axes."""
    from matplotlib.ticker import MaxNLocator

    if x.shape[1] == 3:
        ax = fig.add_subplot(projection="3d", computed_zorder=False)
        if tris is None:
            ax.scatter(*x.T, c=err, cmap=cmap, norm=norm, s=8, depthshade=False)
        else:  # the facets as one surface, each its vertices' mean error
            faces = ax.plot_trisurf(
                *x.T, triangles=tris, linewidth=0.1, edgecolor=(0, 0, 0, 0.25), shade=False
            )
            faces.set_facecolor(cmap(norm(err[tris].mean(axis=1))))
        lo, hi = x.min(axis=0), x.max(axis=0)
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
        ax.set_box_aspect(np.maximum(hi - lo, 1e-3 * (hi - lo).max()))
        ax.view_init(elev=22.0, azim=-58.0)
        ax.set(xlabel="x (m)", ylabel="y (m)", zlabel="z (m)")
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MaxNLocator(3))
        ax.xaxis.labelpad = ax.yaxis.labelpad = 10
        return ax
    ax = fig.add_subplot()
    if tris is None:
        ax.scatter(*x.T, c=err, cmap=cmap, norm=norm, s=10)
    else:
        ax.tripcolor(x[:, 0], x[:, 1], tris, err, cmap=cmap, norm=norm, shading="gouraud")
    ax.set_aspect("equal")
    ax.set(xlabel="x (m)", ylabel="y (m)")
    return ax


def draw(path: Path, net, case, heldout, at: int, rel: float) -> float:
    """MODEL-heldout.png: held-out load ``at`` (relative error ``rel``) drawn on the model's
    deformed shape; the magnification."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    from harness.report.figures import pyplot

    name, fem, model = heldout.names[at], heldout.u_fem[at], heldout.u_model[at]
    umax = float(np.linalg.norm(fem, axis=1).max()) or 1.0
    err = 100.0 * np.linalg.norm(model - fem, axis=1) / umax  # % of the FEM's largest |u|
    k = scale(net.points, fem, model)
    x = net.points + k * model
    held, loaded = regions(net, case, name)
    load = next(l for l in case.loads if l.name == name)
    norm, cmap = Normalize(0.0, float(err.max()) or 1.0), colormaps["viridis"]
    plt = pyplot()
    fig = plt.figure(figsize=(7.0, 5.0))
    ax = _body(fig, x, _triangles(net), err, norm, cmap)
    _mark(ax, x, held, loaded, load.gravity is not None or load.body_force is not None)
    fig.colorbar(
        ScalarMappable(norm, cmap),
        ax=ax,
        shrink=0.7,
        pad=0.15 if net.dim == 3 else 0.04,
        label=f"|u_model - u_FEM| (% of max |u_FEM| = {umax:.3g} m)",
    )
    ax.set_title(
        f"held-out load '{name}' (the worst of {len(heldout.names)}): RMS error "
        f"{100 * rel:.3g} % of the FEM's\nthe model's shape, displacements drawn x{k:g}",
        fontsize=9,
    )
    fig.savefig(path, dpi=100, format="png", bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    return k


def write(vtu: Path, png: Path, net, case, heldout) -> tuple[str, float, float]:
    """Both files (at the paths given: the caller's staged temporaries); (the load drawn,
    its relative error, the magnification)."""
    write_vtu(vtu, net, point_data(net, case, heldout))
    at, rel = worst(net, case, heldout)
    return heldout.names[at], rel, draw(png, net, case, heldout, at, rel)


def sentence(out: Path, shown: tuple[str, float, float]) -> str:
    """The end of calibrate's last line: the two files and what the picture shows."""
    vtu, png = paths(out)
    name, rel, k = shown
    return (
        f"; the fit on the held-out loads: {vtu} (+ {png.name}: '{name}', the worst, "
        f"{100 * rel:.3g} % RMS error, displacements drawn x{k:g})"
    )
