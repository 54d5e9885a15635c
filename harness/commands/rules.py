"""springbench rules fit MESH... --nu NU... --out RULE.json

Fits the coefficients c of the ``learned`` stiffness rule (harness/models/learned_rule.py:
k = k_vanGelder exp(X c), X per-spring features and nu) on a corpus of triangle or
tetrahedron meshes at several Poisson ratios, against answers that need no FEM: the
linear stress states (load sets ``linear2d`` / ``linear3d``: constant, bending, torsion,
shear-gradient and gravity states on the whole boundary, minimal constraints), whose
exact displacements are quadratic fields evaluated at the nodes
(harness/case/linear_states.py ``linear_closed_form``).

Objective (``--objective mean``, the default): the mean over meshes, Poisson ratios and
loads of each load's own relative RMS displacement error ||u - u_exact|| / ||u_exact||
(over all nodes, unit weights); ``log``: the mean of its logarithm. It is minimised by
L-BFGS-B with the adjoint gradient (one extra solve per load: dJ/dk_e = -sum_l
(b_e . lambda_l)(b_e . u_l), K lambda_l = dJ/du_l) from c = 0 (van Gelder's rule) and,
with ``--starts N``, from N - 1 seeded random starts too; the best is kept. 2-D and 3-D
meshes get separate coefficients. Deterministic for given files, flags and seed.

Writes RULE.json: per dimension the feature names, the coefficients, the objective
before (c = 0) and after, and every (mesh, nu)'s mean error before and after; the
corpus (file names, SHA-256, node and cell counts) and the command line. Copy it over
harness/models/learned_rule.json to ship it as the ``learned`` rule.
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.errors import SpringbenchError

HELP = "fit the learned stiffness rule's coefficients on a corpus of meshes (no FEM: exact linear states)"
OBJECTIVES = ("mean", "log")
BOUND = 3.0                # |c_j| <= BOUND: a factor of at most e^3 per unit feature


def add_arguments(p):
    sub = p.add_subparsers(dest="rules_command", metavar="SUBCOMMAND", required=True)
    f = sub.add_parser("fit", help="fit the learned rule's coefficients on meshes and Poisson ratios",
                       description=HELP)
    f.add_argument("meshes", type=Path, nargs="+", metavar="MESH", help="triangle or tetrahedron meshes (meshio)")
    f.add_argument("--nu", type=float, nargs="+", required=True, metavar="NU",
                   help="Poisson ratios in (-1, 0.5) to fit at, e.g. --nu 0.2 0.3 0.4 0.45 (three or more "
                        "determine the nu terms)")
    f.add_argument("--out", type=Path, required=True, metavar="RULE.json", help="the fitted coefficients (JSON)")
    f.add_argument("--objective", choices=OBJECTIVES, default="mean",
                   help="mean (default): the mean relative RMS error of the loads; log: the mean of its log")
    f.add_argument("--maxiter", type=int, default=200, help="L-BFGS-B iterations per start (default 200)")
    f.add_argument("--starts", type=int, default=1,
                   help="starts: c = 0, then seeded random ones (default 1); the best is kept")
    f.add_argument("--seed", type=int, default=0, help="seed of the random starts (>= 0; default 0)")
    f.add_argument("--plane", choices=("stress", "strain"), default="stress", help="2-D meshes: plane stress/strain")
    f.add_argument("--format", default=None, help="mesh format if the file names do not tell (meshio name)")


def _check(args):
    def bad(flag, msg, fix):
        raise SpringbenchError(msg, field=flag, fix=fix)
    for nu in args.nu:
        if not (-1 < nu < 0.5):
            bad("--nu", f"{nu} is out of range", "Poisson ratios in (-1, 0.5), e.g. --nu 0.3 0.45")
    if len(set(args.nu)) < len(args.nu):
        bad("--nu", f"{' '.join(f'{v:g}' for v in args.nu)} repeats a value", "give each Poisson ratio once")
    if args.maxiter < 1:
        bad("--maxiter", f"{args.maxiter} is not a positive number of iterations", "e.g. --maxiter 200")
    if not 1 <= args.starts <= 100:
        bad("--starts", f"{args.starts} is not in 1..100", "e.g. --starts 1 (c = 0 only) or --starts 4")
    if args.seed < 0:
        bad("--seed", f"{args.seed} is negative", "a seed >= 0, e.g. --seed 0")
    if args.out.suffix.lower() != ".json":
        bad("--out", f"'{args.out}' does not end in .json", "e.g. --out rule.json")
    from harness.outputs import check_out_file
    check_out_file(args.out, "--out")
    if len(set(p.resolve() for p in args.meshes)) < len(args.meshes):
        raise SpringbenchError("is given twice", file=str(next(p for i, p in enumerate(args.meshes)
                                                                if p.resolve() in {q.resolve() for q in args.meshes[:i]})),
                               fix="give each mesh once")
    for p in args.meshes:
        if not p.is_file():
            raise SpringbenchError("is a folder, not a mesh file" if p.is_dir() else "no such mesh file",
                                   file=str(p), fix="check the path")


# -- the training set -------------------------------------------------------------------

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
    from harness.case.reader import load_case
    fmt = f"format = {json.dumps(fmt)}\n" if fmt else ""
    text = (f'name = "rules-fit"\ndim = {dim}\n[body]\nshape = "mesh"\nfile = {json.dumps(str(mesh.resolve()))}\n'
            f'{fmt}[material]\nE = 1.0\nnu = {float(nu)!r}\ndensity = 1.0\nplane = "{plane}"\n'
            f'[loads]\nset = "linear{dim}d"\nmagnitude = 0.001\n[reference]\nmax_refine = 0\nmodes = 0\n'
            f'[model]\nkind = "sms"\nplacement = "mesh"\nmasses = "lumped"\nstiffness = ["vangelder"]\n')
    path = folder / "rules-fit.toml"
    path.write_text(text)
    return load_case(path)


def exact_displacements(case, points) -> np.ndarray:
    """(L, n * dim): every load's closed-form displacement at the points."""
    from harness.case.elasticity import element_stiffness
    from harness.case.linear_states import linear_closed_form
    from harness.case.loadsets import ANCHORS
    anchors = np.array([case.body.parts[a][0] for a in ANCHORS[:case.dim]])
    S = np.linalg.inv(element_stiffness(case.material, np.asarray(points, float).mean(0)[None])[0])
    return np.array([linear_closed_form(l, points, S, anchors).ravel() for l in case.loads])


def groups(B, free: np.ndarray, f: np.ndarray, u: np.ndarray) -> tuple[Group, ...]:
    """The loads grouped by their free dofs (L, ndof masks), one Group each."""
    out = []
    for mask in np.unique(free, axis=0):
        rows = np.flatnonzero(np.all(free == mask, axis=1))
        fd = np.flatnonzero(mask)
        out.append(Group(B[fd], f[rows][:, fd], u[rows][:, fd], (u[rows][:, ~mask] ** 2).sum(1),
                         np.linalg.norm(u[rows], axis=1)))
    return tuple(out)


def sample(mesh: Path, nu: float, plane: str = "stress", fmt: str | None = None, folder: Path | None = None,
           u_exact=None, mesh_obj=None) -> Sample:
    """The training sample of one mesh at one nu. ``u_exact`` (L, n*dim) replaces the
    closed forms (a planted answer, for tests)."""
    from harness.io.meshfile import read_mesh
    from harness.mechanics.statics import all_load_arrays
    from harness.models.learned_rule import design, geometry
    from harness.models.sms import build_network
    m = mesh_obj or read_mesh(mesh, fmt)
    with tempfile.TemporaryDirectory(prefix="springbench-rules-") as tmp:
        case = _case(mesh, m.dim, nu, plane, fmt, Path(folder or tmp))
        net = build_network(case)
        names, free, f = all_load_arrays(net, case)
    u = exact_displacements(case, net.points) if u_exact is None else np.asarray(u_exact, float)
    X = design(geometry(net.points, net.springs, net.cells), nu, m.dim)
    return Sample(Path(mesh).name, float(nu), m.dim, np.asarray(net.k, float), X,
                  groups(net.incidence().tocsr(), free, f, u), tuple(names))


# -- the objective and its adjoint gradient -----------------------------------------------

def errors(s: Sample, c, grad: bool = False, objective: str = "mean"):
    """(each load's relative RMS error (L,), and with ``grad`` d J_s / dc (p,)), J_s the
    sample's mean error (``log``: mean log error)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from harness.models.learned_rule import correction
    k = s.k0 * correction(s.X, c)
    n_loads = len(s.loads)
    rel, gk = [], np.zeros(len(k))
    for g in s.groups:
        K = (g.B @ sp.diags(k) @ g.B.T).tocsc()
        lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A")
        U = lu.solve(np.ascontiguousarray(g.f.T))                    # (free, L)
        R = U - g.u.T
        err = np.sqrt((R ** 2).sum(0) + g.fixed2)
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


def fit(samples, objective_name: str = "mean", maxiter: int = 200, starts: int = 1, seed: int = 0,
        bound: float = BOUND, status=None) -> Fit:
    """Minimise the objective over c by L-BFGS-B (bounds +-bound) from c = 0 and
    ``starts - 1`` seeded random starts (normal, sd 0.3); the best result."""
    from scipy.optimize import minimize
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
        res = minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=[(-bound, bound)] * p,
                       options={"maxiter": maxiter, "ftol": 1e-10, "gtol": 1e-7})
        if best is None or res.fun < best[0].fun:
            best = (res, i)
    res, i = best
    return Fit(tuple(float(v) for v in res.x), float(before), float(res.fun), int(res.nit), int(res.nfev),
               str(res.message), i)


# -- the command ---------------------------------------------------------------------------

def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_corpus(paths, fmt=None) -> dict[int, list]:
    """{dim: [(path, Mesh)]} of checked triangle / tetrahedron meshes."""
    from harness.case.mesh_checks import check_mesh
    from harness.io.meshfile import read_mesh
    from harness.models.learned_rule import SIMPLEX
    out: dict[int, list] = {}
    for p in paths:
        m = read_mesh(p, fmt)
        check_mesh(m, str(p))
        if set(m.cells) != {SIMPLEX.get(m.dim)}:
            raise SpringbenchError(f"has {', '.join(sorted(m.cells))} cells", file=str(p),
                                   fix=f"the learned rule is fitted on {SIMPLEX.get(m.dim, 'simplex')} meshes only "
                                       f"(quads and hexahedra use its scale alone)")
        out.setdefault(m.dim, []).append((Path(p), m))
    return out


def main(args) -> int:
    _check(args)
    from harness.models.learned_rule import FEATURES
    corpus = read_corpus(args.meshes, args.format)
    last = [0.0]

    def status(msg):        # at most one line in 5 s
        now = time.monotonic()
        if now - last[0] >= 5.0:
            last[0] = now
            print(f"  {msg}", file=sys.stderr, flush=True)
    dims, t0 = {}, time.monotonic()
    for dim, meshes in sorted(corpus.items()):
        samples = []
        for path, m in meshes:
            for nu in args.nu:
                status(f"{dim}-D: {path.name} at nu = {nu:g}")
                samples.append(sample(path, nu, args.plane, args.format, mesh_obj=m))
        res = fit(samples, args.objective, args.maxiter, args.starts, args.seed, status=status)
        table = []
        for s in samples:
            before, after = errors(s, np.zeros(len(res.coefficients))), errors(s, res.coefficients)
            table.append({"mesh": s.name, "nu": s.nu, "loads": len(s.loads), "mean_error_before": float(before.mean()),
                          "mean_error_after": float(after.mean())})
        dims[str(dim)] = {"features": list(FEATURES[dim]), "coefficients": list(res.coefficients),
                          "objective_before": res.before, "objective_after": res.after,
                          "iterations": res.iterations, "evaluations": res.evaluations, "optimizer": res.message,
                          "best_start": res.start, "samples": table}
        print(f"{dim}-D: {len(meshes)} meshes x {len(args.nu)} nu, objective ({args.objective}) "
              f"{res.before:.4g} (van Gelder, c = 0) -> {res.after:.4g}")
        for name, c in zip(FEATURES[dim], res.coefficients):
            print(f"  c[{name}] = {c:+.4f}")
    data = {"rule": "learned", "family": "k = k_vangelder * exp(sum_j c_j phi_j) (harness/models/learned_rule.py)",
            "dims": dims,
            "corpus": [{"file": p.name, "sha256": _sha256(p), "dim": m.dim, "nodes": len(m.points),
                        "cells": {k: len(v) for k, v in m.cells.items()}}
                       for dim in sorted(corpus) for p, m in corpus[dim]],
            "fit": {"command": "springbench " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["rules"] else
                    _command(args), "nu": list(args.nu), "objective": args.objective,
                    "loads": "linear2d / linear3d states, exact closed forms at the nodes (no FEM)",
                    "plane": args.plane, "maxiter": args.maxiter, "starts": args.starts, "seed": args.seed,
                    "bound": BOUND, "seconds": round(time.monotonic() - t0, 1)}}
    from harness.outputs import atomic_write
    atomic_write(args.out, (json.dumps(data, indent=1) + "\n").encode(), "--out")
    print(f"-> {args.out}")
    return 0


def _command(args) -> str:
    """The command line that reproduces this fit (when not run from the shell)."""
    parts = ["springbench rules fit", *map(str, args.meshes), "--nu", *(f"{v:g}" for v in args.nu),
             "--objective", args.objective, "--maxiter", str(args.maxiter), "--starts", str(args.starts),
             "--seed", str(args.seed), "--out", str(args.out)]
    return " ".join(parts)
