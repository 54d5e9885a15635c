"""The learned stiffness rule's coefficients fitted on a corpus of meshes: the training set
(each mesh's exact linear states, no FEM), the objective (the states' relative misfits)
with its adjoint gradient, and the bounded L-BFGS fit (``springbench rules fit``)."""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import minimize

from harness.case.elasticity import element_stiffness
from harness.case.linear_states import linear_closed_form
from harness.case.loadsets import ANCHORS
from harness.case.reader import load_case
from harness.io.meshfile import read_mesh
from harness.mechanics.statics import all_load_arrays
from harness.models.learned_rule import correction, design, geometry
from harness.models.sms import build_network

OBJECTIVES = ("mean", "log")
BOUND = 3.0  # |c_j| <= BOUND: a factor of at most e^3 per unit feature


@dataclass(frozen=True, eq=False)
class Group:
    """Loads sharing their constraints: B (free dofs, springs) the incidence on the free
    dofs, f (L, free) forces, u (L, free) the exact displacements there, fixed2 (L,) the
    squared exact displacement on the constrained dofs (the model's is 0), norm (L,) the
    exact field's norm over all dofs."""

    B: object
    f: np.ndarray
    u: np.ndarray
    fixed2: np.ndarray
    norm: np.ndarray


@dataclass(frozen=True, eq=False)
class Sample:
    """One mesh at one Poisson ratio: van Gelder's k0 (e,), the features X (e, p), the
    load groups and the load names."""

    name: str
    nu: float
    dim: int
    k0: np.ndarray
    X: np.ndarray
    groups: tuple[Group, ...]
    loads: tuple[str, ...]


def _case(mesh: Path, dim: int, nu: float, plane: str, fmt: str | None, folder: Path):
    """The in-memory case of the linear states on a mesh body (E = 1: errors are relative)."""

    fmt = f"format = {json.dumps(fmt)}\n" if fmt else ""
    text = (
        f'name = "rules-fit"\ndim = {dim}\n[body]\nshape = "mesh"\n'
        f"file = {json.dumps(str(mesh.resolve()))}\n"
        f'{fmt}[material]\nE = 1.0\nnu = {float(nu)!r}\ndensity = 1.0\nplane = "{plane}"\n'
        f'[loads]\nset = "linear{dim}d"\nmagnitude = 0.001\n'
        f"[reference]\nmax_refine = 0\nmodes = 0\n"
        f'[model]\nkind = "sms"\nplacement = "mesh"\nmasses = "lumped"\nstiffness = ["vangelder"]\n'
    )
    path = folder / "rules-fit.toml"
    path.write_text(text)
    return load_case(path)


def exact_displacements(case, points) -> np.ndarray:
    """(L, n * dim): every load's closed-form displacement at the points."""

    anchors = np.array([case.body.parts[a][0] for a in ANCHORS[: case.dim]])
    S = np.linalg.inv(element_stiffness(case.material, np.asarray(points, float).mean(0)[None])[0])
    return np.array([linear_closed_form(l, points, S, anchors).ravel() for l in case.loads])


def groups(B, free: np.ndarray, f: np.ndarray, u: np.ndarray) -> tuple[Group, ...]:
    """The loads grouped by their free dofs (L, ndof masks), one Group each."""
    out = []
    for mask in np.unique(free, axis=0):
        rows = np.flatnonzero(np.all(free == mask, axis=1))
        fd = np.flatnonzero(mask)
        out.append(
            Group(
                B[fd],
                f[rows][:, fd],
                u[rows][:, fd],
                (u[rows][:, ~mask] ** 2).sum(1),
                np.linalg.norm(u[rows], axis=1),
            )
        )
    return tuple(out)


def sample(
    mesh: Path,
    nu: float,
    plane: str = "stress",
    fmt: str | None = None,
    folder: Path | None = None,
    u_exact=None,
    mesh_obj=None,
) -> Sample:
    """The training sample of one mesh at one nu. ``u_exact`` (L, n*dim) replaces the
    closed forms (a planted answer, for tests)."""

    m = mesh_obj or read_mesh(mesh, fmt)
    with tempfile.TemporaryDirectory(prefix="springbench-rules-") as tmp:
        case = _case(mesh, m.dim, nu, plane, fmt, Path(folder or tmp))
        net = build_network(case)
        names, free, f = all_load_arrays(net, case)
    u = exact_displacements(case, net.points) if u_exact is None else np.asarray(u_exact, float)
    X = design(geometry(net.points, net.springs, net.cells), nu, m.dim)
    return Sample(
        Path(mesh).name,
        float(nu),
        m.dim,
        np.asarray(net.k, float),
        X,
        groups(net.incidence().tocsr(), free, f, u),
        tuple(names),
    )


# -- the objective and its adjoint gradient


def errors(s: Sample, c, grad: bool = False, objective: str = "mean"):
    """(each load's relative RMS error (L,), and with ``grad`` d J_s / dc (p,)), J_s the
    sample's mean error (``log``: mean log error)."""

    k = s.k0 * correction(s.X, c)
    n_loads = len(s.loads)
    rel, gk = [], np.zeros(len(k))
    for g in s.groups:
        K = (g.B @ sp.diags(k) @ g.B.T).tocsc()
        lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A")
        U = lu.solve(np.ascontiguousarray(g.f.T))  # (free, L)
        R = U - g.u.T
        err = np.sqrt((R**2).sum(0) + g.fixed2)
        r = err / g.norm
        rel.append(r)
        if grad:
            w = 1.0 / (err * g.norm * n_loads) * (1.0 / r if objective == "log" else 1.0)
            Lam = lu.solve(np.ascontiguousarray(R * w))
            gk -= np.einsum("el,el->e", g.B.T @ Lam, g.B.T @ U)
    rel = np.concatenate(rel)
    if not grad:
        return rel
    return rel, s.X.T @ (gk * k)


def objective(samples, c, objective: str = "mean"):
    """(J, dJ/dc): the mean over samples of their J_s."""
    J, G = 0.0, 0.0
    for s in samples:
        r, g = errors(s, c, True, objective)
        J += float(np.mean(np.log(r)) if objective == "log" else np.mean(r))
        G = G + g
    return J / len(samples), np.asarray(G, float) / len(samples)


@dataclass(frozen=True)
class Fit:
    """The fitted coefficients, the objective at c = 0 and after, the optimiser's record."""

    coefficients: tuple[float, ...]
    before: float
    after: float
    iterations: int
    evaluations: int
    message: str
    start: int


def fit(
    samples,
    objective_name: str = "mean",
    maxiter: int = 200,
    starts: int = 1,
    seed: int = 0,
    bound: float = BOUND,
    status=None,
) -> Fit:
    """Minimise the objective over c by L-BFGS-B (bounds +-bound) from c = 0 and
    ``starts - 1`` seeded random starts (normal, sd 0.3); the best result."""

    p = samples[0].X.shape[1]
    rng = np.random.default_rng(seed)
    x0s = [np.zeros(p)] + [np.clip(rng.normal(0, 0.3, p), -bound, bound) for _ in range(starts - 1)]
    before = objective(samples, np.zeros(p), objective_name)[0]
    best = None
    for i, x0 in enumerate(x0s):
        calls = [0]

        def fun(c):
            calls[0] += 1
            J, g = objective(samples, c, objective_name)
            if status:
                status(f"start {i + 1}/{len(x0s)}, evaluation {calls[0]}: J = {J:.6g}")
            return J, g

        res = minimize(
            fun,
            x0,
            jac=True,
            method="L-BFGS-B",
            bounds=[(-bound, bound)] * p,
            options={"maxiter": maxiter, "ftol": 1e-10, "gtol": 1e-7},
        )
        if best is None or res.fun < best[0].fun:
            best = (res, i)
    res, i = best
    return Fit(
        tuple(float(v) for v in res.x),
        float(before),
        float(res.fun),
        int(res.nit),
        int(res.nfev),
        str(res.message),
        i,
    )
