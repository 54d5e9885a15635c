"""Benchmark of the FEM reference: P2 assembly + solve times in 2-D and 3-D (sparse
direct vs pyamg smoothed aggregation on the same system), and point evaluation with the
KD-tree locator for 1e6 points against scikit-fem's own ``Basis.probes`` on a smaller
count (its points x elements matrix limits it), as a per-point time ratio; and the
accuracy of the reference's methods on the Deussen sec6 cube's shear (task "accuracy")
against the independent truth of tests/independent/ (loaded by path)."""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import skfem

from harness.bench.reference_accuracy import LOAD, accuracy_rows, shape_rows, shear_case
from harness.case.elasticity import isotropic_compliance, plane
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


def _solve_row(dim: int, d, solver: str, seconds, t_asm, residual, ratio, note) -> dict:
    """One row of task "solve": a P2 system of d.ndof dofs solved by ``solver``."""
    return dict(
        task="solve",
        dim=dim,
        element="P2 tri" if dim == 2 else "P2 tet",
        n_dofs=d.ndof,
        solver=solver,
        seconds=seconds,
        assembly_seconds=t_asm,
        residual=residual,
        ratio=ratio,
        note=note,
    )


def run(quick: bool = False) -> pd.DataFrame:
    rows = []
    sizes_2d = [16, 32] if quick else [32, 64, 128]
    for n in steps(sizes_2d, "bench reference 2-D", "size"):
        d, A, b, R, t_asm = _system("tri", n)
        t_dir, r_dir = _time_solve(A, b, R, "direct")
        rows.append(_solve_row(2, d, "direct", t_dir, t_asm, r_dir, 1.0, "baseline: direct"))
        t_amg, r_amg = _time_solve(A, b, R, "amg")
        ratio, note = t_dir / t_amg, "ratio = direct / amg time"
        rows.append(_solve_row(2, d, "amg", t_amg, t_asm, r_amg, ratio, note))
    sizes_3d = [(3, True), (4, True)] if quick else [(4, True), (6, True), (10, False)]
    for n, with_direct in steps(sizes_3d, "bench reference 3-D", "size"):
        d, A, b, R, t_asm = _system("tet", n)
        t_amg, r_amg = _time_solve(A, b, R, "amg")
        if with_direct:
            t_dir, r_dir = _time_solve(A, b, R, "direct")
            rows.append(_solve_row(3, d, "direct", t_dir, t_asm, r_dir, 1.0, "baseline: direct"))
            ratio, note = t_dir / t_amg, "ratio = direct / amg time"
        else:
            ratio, note = np.nan, "direct skipped (too slow)"
        rows.append(_solve_row(3, d, "amg", t_amg, t_asm, r_amg, ratio, note))
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
    rows.append(
        dict(
            task="probe",
            dim=2,
            element="P2 tri",
            n_dofs=basis.N,
            solver="skfem probes",
            seconds=t_sk,
            points=n_small,
            ratio=1.0,
            residual=agree,
            note=f"baseline: Basis.probes on {mesh.t.shape[1]} elements",
        )
    )
    rows.append(
        dict(
            task="probe",
            dim=2,
            element="P2 tri",
            n_dofs=basis.N,
            solver="kd-tree locator",
            seconds=t_loc,
            points=n_big,
            ratio=(t_sk / n_small) / (t_loc / n_big),
            residual=agree,
            note="ratio = per-point time of probes / locator; residual = max difference",
        )
    )
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
        case, _ = shear_case(Path(tmp), "thin", {}, (10.0, 1.0, 1.0), 0.49)
        load = next(l for l in case.loads if l.name == LOAD)
        mirror = mirror_of(case, load)
        for n, with_direct in (
            [(3, True), (4, True)] if quick else [(4, True), (6, True), (8, False)]
        ):
            d = Discretisation(
                tensor_mesh(
                    lower_half(graded_axes(np.zeros(3), np.array([10.0, 1.0, 1.0]), n), mirror)
                ),
                "hex",
                "P2",
            )
            base = np.nan
            for method in (["direct"] if with_direct else []) + ["tensor"]:
                c = dataclasses.replace(
                    case, reference=dataclasses.replace(case.reference, solver=method)
                )
                info: list = []
                t0 = time.perf_counter()
                solve_mesh(c, d.mesh, loads={LOAD}, records=info, mirror=mirror, disc=d)
                wall = time.perf_counter() - t0
                rec = info[0]
                base = rec.seconds if method == "direct" else base
                rows.append(
                    dict(
                        task="solve",
                        dim=3,
                        element="Q2 hex graded",
                        n_dofs=rec.n,
                        solver=rec.method,
                        seconds=rec.seconds,
                        assembly_seconds=wall - rec.seconds,
                        residual=rec.residual,
                        ratio=1.0 if method == "direct" else base / rec.seconds,
                        note=(
                            f"baseline: direct; 10:1 box nu 0.49 {LOAD} quarter, n = {n}; "
                            "assembly_seconds: K, loads, constraints"
                            if method == "direct"
                            else f"ratio = direct / tensor time; {rec.iterations} iterations; "
                            f"n = {n}; "
                            + (
                                "matrix-free (K never assembled)"
                                if rec.matrix_free
                                else "assembled"
                            )
                            + ("" if with_direct else ", direct skipped (too slow)")
                        ),
                    )
                )
    return rows
