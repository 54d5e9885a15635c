"""Benchmark of the FEM reference: P2 assembly + solve times in 2-D and 3-D (sparse
direct vs pyamg smoothed aggregation on the same system), and point evaluation with the
KD-tree locator for 1e6 points against scikit-fem's own ``Basis.probes`` on a smaller
count (its points x elements matrix limits it), as a per-point time ratio; and the
accuracy of the reference's methods on the Deussen sec6 cube's shear (task "accuracy")
against the independent truth of tests/independent_elasticity.py (loaded by path)."""

from __future__ import annotations

import dataclasses
import importlib.util
import resource
import sys
import tempfile
import time
import tomllib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import skfem

from harness.case.elasticity import isotropic_compliance, plane
from harness.case.reader import load_case
from harness.progress import steps
from reference.fem import Discretisation
from reference.locate import Locator
from reference.solvers import sparse


def _system(cell: str, n: int):
    dim = 2 if cell == "tri" else 3
    M = skfem.MeshTri if dim == 2 else skfem.MeshTet
    mesh = M.init_tensor(*[np.linspace(0, 1 + i, n * (1 + i) + 1) for i in range(dim)])
    t0 = time.perf_counter()
    d = Discretisation(mesh, cell, "P2")
    C = np.linalg.inv(isotropic_compliance(1000.0, 0.3))
    C = plane(C, "stress") if dim == 2 else C
    K = d.stiffness(np.tile(C, (d.nelems, 1, 1)))
    fixed = d.part_dofs(lambda x: x[0] < 1e-12, range(dim))
    F = d.traction_load(d.part_facets(lambda x: x[0] > 1 - 1e-12), [0.0] * (dim - 1) + [-1.0])
    free = np.setdiff1d(np.arange(d.ndof), fixed)
    A = K[free][:, free].tocsr()
    return d, A, F[free], d.rigid_modes()[free], time.perf_counter() - t0


def _time_solve(A, b, R, method):
    t0 = time.perf_counter()
    x = sparse.solve(A, b, method, R)
    sec = time.perf_counter() - t0
    return sec, float(np.linalg.norm(A @ x - b) / np.linalg.norm(b))


def run(quick: bool = False) -> pd.DataFrame:
    rows = []
    sizes_2d = [16, 32] if quick else [32, 64, 128]
    for n in steps(sizes_2d, "bench reference 2-D", "size"):
        d, A, b, R, t_asm = _system("tri", n)
        t_dir, r_dir = _time_solve(A, b, R, "direct")
        rows.append(dict(task="solve", dim=2, element="P2 tri", n_dofs=d.ndof, solver="direct",
                         seconds=t_dir, assembly_seconds=t_asm, residual=r_dir, ratio=1.0,
                         note="baseline: direct"))
        t_amg, r_amg = _time_solve(A, b, R, "amg")
        rows.append(dict(task="solve", dim=2, element="P2 tri", n_dofs=d.ndof, solver="amg",
                         seconds=t_amg, assembly_seconds=t_asm, residual=r_amg, ratio=t_dir / t_amg,
                         note="ratio = direct / amg time"))
    sizes_3d = [(3, True), (4, True)] if quick else [(4, True), (6, True), (10, False)]
    for n, with_direct in steps(sizes_3d, "bench reference 3-D", "size"):
        d, A, b, R, t_asm = _system("tet", n)
        t_amg, r_amg = _time_solve(A, b, R, "amg")
        t_dir, r_dir = _time_solve(A, b, R, "direct") if with_direct else (np.nan, np.nan)
        if with_direct:
            rows.append(dict(task="solve", dim=3, element="P2 tet", n_dofs=d.ndof, solver="direct",
                             seconds=t_dir, assembly_seconds=t_asm, residual=r_dir, ratio=1.0,
                             note="baseline: direct"))
        rows.append(dict(task="solve", dim=3, element="P2 tet", n_dofs=d.ndof, solver="amg",
                         seconds=t_amg, assembly_seconds=t_asm, residual=r_amg,
                         ratio=t_dir / t_amg if with_direct else np.nan,
                         note="ratio = direct / amg time" if with_direct else "direct skipped (too slow)"))
    # probes: 2-D P2 mesh with ~8k elements
    mesh = skfem.MeshTri.init_tensor(np.linspace(0, 2, 91), np.linspace(0, 1, 46))
    basis = skfem.CellBasis(mesh, skfem.ElementTriP2())
    u = np.sin(basis.doflocs[0]) * basis.doflocs[1]
    rng = np.random.default_rng(0)
    n_big, n_small = (100_000, 1_000) if quick else (1_000_000, 2_000)
    x_big = rng.uniform([0, 0], [2, 1], (n_big, 2))
    t0 = time.perf_counter()
    loc = Locator(mesh)
    v = loc.evaluate(basis, u, x_big)
    t_loc = time.perf_counter() - t0
    xs = x_big[:n_small]
    t0 = time.perf_counter()
    vs = basis.probes(xs.T) @ u
    t_sk = time.perf_counter() - t0
    agree = float(np.abs(vs - v[:n_small]).max())
    rows.append(dict(task="probe", dim=2, element="P2 tri", n_dofs=basis.N, solver="skfem probes",
                     seconds=t_sk, points=n_small, ratio=1.0, residual=agree,
                     note=f"baseline: Basis.probes on {mesh.t.shape[1]} elements"))
    rows.append(dict(task="probe", dim=2, element="P2 tri", n_dofs=basis.N, solver="kd-tree locator",
                     seconds=t_loc, points=n_big, ratio=(t_sk / n_small) / (t_loc / n_big), residual=agree,
                     note="ratio = per-point time of probes / locator; residual = max difference"))
    rows += graded_solve_rows(quick)
    rows += accuracy_rows(quick)
    if not quick:
        rows += shape_rows()
    return pd.DataFrame(rows)


def graded_solve_rows(quick: bool = False) -> list[dict]:
    """The graded reference's own systems: the 10:1 box's shear-xz at nu = 0.49 on its
    quarter at levels n, solved by the multifrontal Cholesky (baseline, 'direct') and by
    CG with the fast-diagonalisation preconditioner ('tensor', K applied without assembly),
    solver seconds (and, apart, the rest of the call: assembly, loads, constraints)."""

    from reference.graded.meshes import graded_axes, tensor_mesh
    from reference.graded.symmetry import lower_half, mirror_of
    from reference.problem import solve_mesh
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        case, _ = _shear_case(Path(tmp), "thin", {}, (10.0, 1.0, 1.0), 0.49)
        load = next(l for l in case.loads if l.name == LOAD)
        mirror = mirror_of(case, load)
        for n, with_direct in ([(3, True), (4, True)] if quick else [(4, True), (6, True), (8, False)]):
            d = Discretisation(tensor_mesh(lower_half(graded_axes(np.zeros(3), np.array([10.0, 1.0, 1.0]), n),
                                                      mirror)), "hex", "P2")
            base = np.nan
            for method in (["direct"] if with_direct else []) + ["tensor"]:
                c = dataclasses.replace(case, reference=dataclasses.replace(case.reference, solver=method))
                info: list = []
                t0 = time.perf_counter()
                solve_mesh(c, d.mesh, loads={LOAD}, records=info, mirror=mirror, disc=d)
                wall = time.perf_counter() - t0
                rec = info[0]
                base = rec.seconds if method == "direct" else base
                rows.append(dict(task="solve", dim=3, element="Q2 hex graded", n_dofs=rec.n, solver=rec.method,
                                 seconds=rec.seconds, assembly_seconds=wall - rec.seconds, residual=rec.residual,
                                 ratio=1.0 if method == "direct" else base / rec.seconds,
                                 note=(f"baseline: direct; 10:1 box nu 0.49 {LOAD} quarter, n = {n}; assembly_seconds: "
                                       "K, loads, constraints" if method == "direct"
                                       else f"ratio = direct / tensor time; {rec.iterations} iterations; n = {n}; "
                                       + ("matrix-free (K never assembled)" if rec.matrix_free else "assembled")
                                       + ("" if with_direct else ", direct skipped (too slow)"))))
    return rows


# -- accuracy against the independent truth ----------------------------------------------

ROOT = Path(__file__).resolve().parents[2]
INDEPENDENT = ROOT / "tests" / "independent_elasticity.py"
SEC6 = ROOT / "cases" / "deussen1995" / "sec6_box3d.toml"
LOAD = "shear-xz"
# the truth: the independent quarter solve (beta 2.5, knot 3/4: the grid points are nodes of
# every level), Richardson over the last three levels
TRUTH_LEVELS = {True: (8, 12, 16), False: (16, 20, 24)}
TRUTH_BETA, TRUTH_KNOT = 2.5, 0.75


def _independent():
    """The module tests/independent_elasticity.py, or None (with a message) if absent."""
    if not INDEPENDENT.is_file():
        print(f"bench reference: {INDEPENDENT} not found: the accuracy rows are skipped "
              "(they need the independent truth from the repository's tests/)", file=sys.stderr)
        return None
    spec = importlib.util.spec_from_file_location("independent_elasticity", INDEPENDENT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _shear_case(folder: Path, name: str, reference: dict, size=None, nu=None, nine: bool = False):
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
    loads = f'[loads]\nset = "basic3d"\nmagnitude = {s}' if nine else f"""[[loads.case]]
name = "{LOAD}"
[[loads.case.constraint]]
part = "z0"
components = ["all"]
[[loads.case.traction]]
part = "z1"
vector = [{s}, 0.0, 0.0]"""
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
    lv = ie.shear_levels(size, case.material.E, case.material.nu, s, points - lo, levels, TRUTH_BETA,
                         knot=TRUTH_KNOT)
    u, change, p = ie.extrapolate_levels([v for _, v, *_ in lv], levels)
    return points, u, dict(change=change, order=p, seconds=time.perf_counter() - t0, n_dofs=lv[-1][2])


def _accuracy_row(method, sol, u, u_true, estimate, seconds, note="", truth_change=0.0):
    """One accuracy row. ``bound_ok``: the estimate bounds the error at every point, up to
    the truth's own uncertainty (its relative change ``truth_change`` times the largest
    displacement: a smaller error cannot be told from zero)."""
    scale = float(np.linalg.norm(u_true, axis=1).max())
    err = np.linalg.norm(u - u_true, axis=1)
    row = dict(task="accuracy", dim=3, element="P2 tet" if sol.cell == "tet" else "Q2 hex", method=method,
               n_dofs=sol.n_dofs, seconds=seconds, true_error=float(err.max()) / scale, points=len(u_true),
               note=note)
    if estimate is None or not np.all(np.isfinite(estimate)):
        row.update(estimate=np.nan, bound_ok=np.nan)
    else:
        row.update(estimate=float(np.max(estimate)) / scale,
                   bound_ok=bool(np.all(estimate + truth_change * scale >= err)))
    return row


def accuracy_rows(quick: bool = False) -> list[dict]:
    """True errors of the reference on the sec6 cube's shear-xz at the 4 x 4 x 4 grid: uniform
    P2 tetrahedra (one level), the graded Q2 levels' finest plain field, and their
    Richardson extrapolant with its per-point estimate."""
    import reference
    ie = _independent()
    if ie is None:
        return [dict(task="accuracy", note=f"skipped: {INDEPENDENT.relative_to(ROOT)} not found")]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base, s = _shear_case(tmp, "truth", {})
        points, u_true, info = _truth(ie, base, s, quick)
        rows.append(dict(task="accuracy", dim=3, element="Q2 hex", method="independent truth",
                         n_dofs=info["n_dofs"], seconds=info["seconds"], true_error=np.nan,
                         estimate=info["change"], points=len(points),
                         note=f"quarter, levels {TRUTH_LEVELS[quick]}, beta {TRUTH_BETA}, knot {TRUTH_KNOT}, "
                              f"order {info['order']:.2f}; estimate = change of the extrapolant"))
        tets = (2, 3, 4, 6) if quick else (2, 3, 4, 5, 6, 8, 12)
        for div in tets:
            case, _ = _shear_case(tmp, f"tet{div}", dict(method="refine", cell="tet", divisions=div, max_refine=0))
            sol = reference.solve(case)
            u = sol.displacement(points, LOAD)
            rows.append(_accuracy_row("uniform P2 tet", sol, u, u_true, sol.error_estimate(points, LOAD),
                                      sol.seconds, f"divisions {div}, no refinement"))
        graded = [(None, None)] + ([(4, 2), (6, 2)] if quick else [(4, 2), (6, 2), (8, 2), (10, 2)])
        for last, n_more in graded:
            keys = dict(method="graded")
            if last is not None:       # levels last - 2 .. last cells per end zone, no early stop
                keys.update(divisions=2 * (last - n_more), max_refine=n_more, tol=1e-12)
            case, _ = _shear_case(tmp, f"graded{last}", keys)
            sol = reference.solve(case)
            ns = list(sol.levels.ns)
            what = ("defaults" if last is None else f"levels n = {ns}") + ", solved on a quarter (mirror symmetry)"
            vals, _ = sol.levels.values(points, LOAD)
            rows.append(_accuracy_row("graded Q2 finest level", sol, vals[-1], u_true, None, sol.seconds,
                                      f"{what}; plain field of n = {ns[-1]}"))
            rows.append(_accuracy_row("graded Q2 + Richardson", sol, sol.displacement(points, LOAD), u_true,
                                      sol.error_estimate(points, LOAD), sol.seconds,
                                      f"{what}; order {sol.levels.orders.get(LOAD, np.nan):.2f}", info["change"]))
    return rows


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
        case, _ = _shear_case(Path(tmp), "nine", {}, size, nu, nine=True)
        t0 = time.perf_counter()
        sol = reference.solve(case, cache=False)
        seconds = time.perf_counter() - t0
    return dict(seconds=seconds, peak_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
                u=sol.displacement(points, LOAD), estimate=sol.error_estimate(points, LOAD), n_dofs=sol.n_dofs,
                ns=list(sol.levels.ns), methods=sorted({r.method for r in sol.solver}))


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
            case, s = _shear_case(Path(tmp), "shape", {}, size, nu)
            t0 = time.perf_counter()
            lv = ie.shear_levels(size, case.material.E, nu, s, points, levels, TRUTH_BETA, knot=TRUTH_KNOT,
                                 long_axes=True)
            truth, change, _ = ie.extrapolate_levels([v for _, v, *_ in lv], levels)
            t_truth = time.perf_counter() - t0
            sol = reference.solve(case, cache=False)
            row = _accuracy_row("graded Q2 + Richardson", sol, sol.displacement(points, LOAD), truth,
                                sol.error_estimate(points, LOAD), sol.seconds,
                                f"box {size}, nu {nu}, defaults: levels n = {list(sol.levels.ns)}; truth levels "
                                f"{levels} ({t_truth:.0f} s), its relative change {change:.1e}", change)
            rows.append(row)
            if size[0] / size[1] < 10:
                continue
            with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
                r = pool.submit(_nine_loads, size, nu, points).result()
            row = _accuracy_row("graded Q2 + Richardson, nine loads", sol, r["u"], truth, r["estimate"],
                                r["seconds"], f"box {size}, nu {nu}, basic3d (nine loads), defaults: levels n = "
                                f"{r['ns']}, solvers {r['methods']}; peak memory {r['peak_gb']:.2f} GB "
                                f"(its own process); shear-xz scored", change)
            rows.append(dict(row, n_dofs=r["n_dofs"], peak_gbytes=r["peak_gb"]))
    return rows
