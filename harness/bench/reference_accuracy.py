"""Accuracy of the FEM reference's methods (``springbench bench reference``, task
"accuracy"): the Deussen sec6 cube's shear and nine loads on two shapes, against the
independent truth of tests/independent/ (loaded by path)."""

from __future__ import annotations

import importlib.util
import resource
import sys
import tempfile
import time
import tomllib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from harness.case.reader import load_case

ROOT = Path(__file__).resolve().parents[2]
INDEPENDENT = ROOT / "tests" / "independent"
SEC6 = ROOT / "cases" / "deussen1995" / "sec6_box3d.toml"
LOAD = "shear-xz"
# the truth: the independent quarter solve (beta 2.5, knot 3/4: the grid points are nodes of
# every level), Richardson over the last three levels
TRUTH_LEVELS = {True: (8, 12, 16), False: (16, 20, 24)}
TRUTH_BETA, TRUTH_KNOT = 2.5, 0.75


def _independent():
    """The package tests/independent/, or None (with a message) if absent."""
    if not (INDEPENDENT / "__init__.py").is_file():
        print(
            f"bench reference: {INDEPENDENT} not found: the accuracy rows are skipped "
            "(they need the independent truth from the repository's tests/)",
            file=sys.stderr,
        )
        return None
    spec = importlib.util.spec_from_file_location(
        "independent_elasticity", INDEPENDENT / "__init__.py", submodule_search_locations=[]
    )
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # its modules import each other relatively
    spec.loader.exec_module(mod)
    return mod


def shear_case(folder: Path, name: str, reference: dict, size=None, nu=None, nine: bool = False):
    """The sec6 cube (body and material of cases/deussen1995/sec6_box3d.toml; or another
    ``size`` / ``nu``) with the one load shear-xz (z0 clamped, traction s e_x on z1), or
    with ``nine`` the nine loads of basic3d (whose shear-xz is the same), and the given
    [reference] keys."""
    raw = tomllib.loads(SEC6.read_text())
    body, mat = dict(raw["body"]), dict(raw["material"])
    body.update({} if size is None else {"size": list(size), "origin": [0.0, 0.0, 0.0]})
    mat.update({} if nu is None else {"nu": nu})
    s = float(raw.get("loads", {}).get("magnitude", 1.0))

    def val(v):
        return f'"{v}"' if isinstance(v, str) else repr(v)

    ref = "\n".join(f"{k} = {val(v)}" for k, v in reference.items())
    loads = (
        f'[loads]\nset = "basic3d"\nmagnitude = {s}'
        if nine
        else f"""[[loads.case]]
name = "{LOAD}"
[[loads.case.constraint]]
part = "z0"
components = ["all"]
[[loads.case.traction]]
part = "z1"
vector = [{s}, 0.0, 0.0]"""
    )
    text = f"""name = "{name}"
dim = 3
[body]
shape = "box"
origin = {list(map(float, body.get("origin", [0.0, 0.0, 0.0])))}
size = {list(map(float, body["size"]))}
[material]
E = {float(mat["E"])}
nu = {float(mat["nu"])}
{loads}
[reference]
{ref}
"""
    path = folder / f"{name}.toml"
    path.write_text(text)
    return load_case(path), s


def _truth(ie, case, s, quick: bool):
    lo, hi = case.body.bbox()
    size = tuple(float(v) for v in hi - lo)
    axes = [np.linspace(lo[d], hi[d], 4) for d in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    levels = TRUTH_LEVELS[quick]
    t0 = time.perf_counter()
    lv = ie.shear_levels(
        size, case.material.E, case.material.nu, s, points - lo, levels, TRUTH_BETA, knot=TRUTH_KNOT
    )
    u, change, p = ie.extrapolate_levels([v for _, v, *_ in lv], levels)
    return (
        points,
        u,
        dict(change=change, order=p, seconds=time.perf_counter() - t0, n_dofs=lv[-1][2]),
    )


def _accuracy_row(method, sol, u, u_true, estimate, seconds, note="", truth_change=0.0):
    """One accuracy row. ``bound_ok``: the estimate bounds the error at every point, up to
    the truth's own uncertainty (its relative change ``truth_change`` times the largest
    displacement: a smaller error cannot be told from zero)."""
    scale = float(np.linalg.norm(u_true, axis=1).max())
    err = np.linalg.norm(u - u_true, axis=1)
    row = dict(
        task="accuracy",
        dim=3,
        element="P2 tet" if sol.cell == "tet" else "Q2 hex",
        method=method,
        n_dofs=sol.n_dofs,
        seconds=seconds,
        true_error=float(err.max()) / scale,
        points=len(u_true),
        note=note,
    )
    if estimate is None or not np.all(np.isfinite(estimate)):
        row.update(estimate=np.nan, bound_ok=np.nan)
    else:
        row.update(
            estimate=float(np.max(estimate)) / scale,
            bound_ok=bool(np.all(estimate + truth_change * scale >= err)),
        )
    return row


def _uniform_rows(tmp: Path, points, u_true, quick: bool) -> list[dict]:
    """Uniform P2 tetrahedra, one level per division count."""
    import reference

    rows = []
    for div in (2, 3, 4, 6) if quick else (2, 3, 4, 5, 6, 8, 12):
        case, _ = shear_case(
            tmp, f"tet{div}", dict(method="refine", cell="tet", divisions=div, max_refine=0)
        )
        sol = reference.solve(case)
        u = sol.displacement(points, LOAD)
        est = sol.error_estimate(points, LOAD)
        note = f"divisions {div}, no refinement"
        rows.append(_accuracy_row("uniform P2 tet", sol, u, u_true, est, sol.seconds, note))
    return rows


def _graded_rows(tmp: Path, points, u_true, quick: bool, change: float) -> list[dict]:
    """The graded Q2 levels: the finest plain field and the Richardson extrapolant, for the
    defaults and for fixed level sequences."""
    import reference

    rows = []
    graded = [(None, None)] + ([(4, 2), (6, 2)] if quick else [(4, 2), (6, 2), (8, 2), (10, 2)])
    for last, n_more in graded:
        keys = dict(method="graded")
        if last is not None:  # levels last - 2 .. last cells per end zone, no early stop
            keys.update(divisions=2 * (last - n_more), max_refine=n_more, tol=1e-12)
        case, _ = shear_case(tmp, f"graded{last}", keys)
        sol = reference.solve(case)
        ns = list(sol.levels.ns)
        what = (
            "defaults" if last is None else f"levels n = {ns}"
        ) + ", solved on a quarter (mirror symmetry)"
        vals, _ = sol.levels.values(points, LOAD)
        rows.append(
            _accuracy_row(
                "graded Q2 finest level",
                sol,
                vals[-1],
                u_true,
                None,
                sol.seconds,
                f"{what}; plain field of n = {ns[-1]}",
            )
        )
        rows.append(
            _accuracy_row(
                "graded Q2 + Richardson",
                sol,
                sol.displacement(points, LOAD),
                u_true,
                sol.error_estimate(points, LOAD),
                sol.seconds,
                f"{what}; order {sol.levels.orders.get(LOAD, np.nan):.2f}",
                change,
            )
        )
    return rows


def accuracy_rows(quick: bool = False) -> list[dict]:
    """True errors of the reference on the sec6 cube's shear-xz at the 4 x 4 x 4 grid: uniform
    P2 tetrahedra (one level), the graded Q2 levels' finest plain field, and their
    Richardson extrapolant with its per-point estimate."""
    ie = _independent()
    if ie is None:
        return [dict(task="accuracy", note=f"skipped: {INDEPENDENT.relative_to(ROOT)} not found")]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base, s = shear_case(tmp, "truth", {})
        points, u_true, info = _truth(ie, base, s, quick)
        truth = dict(
            task="accuracy",
            dim=3,
            element="Q2 hex",
            method="independent truth",
            n_dofs=info["n_dofs"],
            seconds=info["seconds"],
            true_error=np.nan,
            estimate=info["change"],
            points=len(points),
            note=f"quarter, levels {TRUTH_LEVELS[quick]}, beta {TRUTH_BETA}, knot "
            f"{TRUTH_KNOT}, "
            f"order {info['order']:.2f}; estimate = change of the extrapolant",
        )
        return [
            truth,
            *_uniform_rows(tmp, points, u_true, quick),
            *_graded_rows(tmp, points, u_true, quick, info["change"]),
        ]


# thin and nearly incompressible boxes at default settings; the
# truth's levels are those at which the independent solver still converges there. The truth
# grades a long axis like the short ones near its end faces (long_axes): with one power zone
# over a third of the 10:1 box's length its cells there are 2.5x coarser, the order at the
# loaded end edges 2.19-2.28 and its extrapolant 6e-5 off; with it, orders 2.62, 2.60, 2.59 on
# the triples of n = 12..28 and extrapolants within 4.8e-6 of each other
SHAPES = (((10.0, 1.0, 1.0), 0.49, (16, 20, 24)), ((3.0, 3.0, 3.0), 0.49, (8, 12, 16)))


def _nine_loads(size, nu, points) -> dict:
    """In a fresh process: the default graded reference of basic3d's nine loads on a box
    of ``size`` and ``nu`` (sec6's E and s): wall seconds, the process's peak RSS, and
    shear-xz with its estimate at ``points``."""

    import reference

    with tempfile.TemporaryDirectory() as tmp:
        case, _ = shear_case(Path(tmp), "nine", {}, size, nu, nine=True)
        t0 = time.perf_counter()
        sol = reference.solve(case, cache=False)
        seconds = time.perf_counter() - t0
    return dict(
        seconds=seconds,
        peak_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
        u=sol.displacement(points, LOAD),
        estimate=sol.error_estimate(points, LOAD),
        n_dofs=sol.n_dofs,
        ns=list(sol.levels.ns),
        methods=sorted({r.method for r in sol.solver}),
    )


def shape_rows() -> list[dict]:
    """True error of the default graded reference of shear-xz on SHAPES (sec6's E and s);
    for the 10:1 box also the whole case (basic3d's nine loads) in a process of its own:
    seconds and peak memory, the issue's "<= 120 s, <= 4 GB per case"."""
    import multiprocessing

    import reference

    ie = _independent()
    if ie is None:
        return []
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for size, nu, levels in SHAPES:
            axes = [np.linspace(0.0, a, 4) for a in size]
            points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            case, s = shear_case(Path(tmp), "shape", {}, size, nu)
            t0 = time.perf_counter()
            lv = ie.shear_levels(
                size,
                case.material.E,
                nu,
                s,
                points,
                levels,
                TRUTH_BETA,
                knot=TRUTH_KNOT,
                long_axes=True,
            )
            truth, change, _ = ie.extrapolate_levels([v for _, v, *_ in lv], levels)
            t_truth = time.perf_counter() - t0
            sol = reference.solve(case, cache=False)
            row = _accuracy_row(
                "graded Q2 + Richardson",
                sol,
                sol.displacement(points, LOAD),
                truth,
                sol.error_estimate(points, LOAD),
                sol.seconds,
                f"box {size}, nu {nu}, defaults: levels n = {list(sol.levels.ns)}; truth levels "
                f"{levels} ({t_truth:.0f} s), its relative change {change:.1e}",
                change,
            )
            rows.append(row)
            if size[0] / size[1] < 10:
                continue
            with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
                r = pool.submit(_nine_loads, size, nu, points).result()
            row = _accuracy_row(
                "graded Q2 + Richardson, nine loads",
                sol,
                r["u"],
                truth,
                r["estimate"],
                r["seconds"],
                f"box {size}, nu {nu}, basic3d (nine loads), defaults: levels n = "
                f"{r['ns']}, solvers {r['methods']}; peak memory {r['peak_gb']:.2f} GB "
                f"(its own process); shear-xz scored",
                change,
            )
            rows.append(dict(row, n_dofs=r["n_dofs"], peak_gbytes=r["peak_gb"]))
    return rows
