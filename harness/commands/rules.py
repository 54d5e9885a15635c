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
import time
from pathlib import Path

import numpy as np

from harness.errors import SpringbenchError
from harness.optimize.rule_fit import BOUND, OBJECTIVES, errors, fit, sample

HELP = (
    "fit the learned stiffness rule's coefficients on a corpus of meshes "
    "(no FEM: exact linear states)"
)


def add_arguments(p):
    sub = p.add_subparsers(dest="rules_command", metavar="SUBCOMMAND", required=True)
    f = sub.add_parser(
        "fit",
        help="fit the learned rule's coefficients on meshes and Poisson ratios",
        description=HELP,
    )
    f.add_argument(
        "meshes",
        type=Path,
        nargs="+",
        metavar="MESH",
        help="triangle or tetrahedron meshes (meshio)",
    )
    f.add_argument(
        "--nu",
        type=float,
        nargs="+",
        required=True,
        metavar="NU",
        help="Poisson ratios in (-1, 0.5) to fit at, e.g. --nu 0.2 0.3 0.4 0.45 (three or more "
        "determine the nu terms)",
    )
    f.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="RULE.json",
        help="the fitted coefficients (JSON)",
    )
    f.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default="mean",
        help="mean (default): the mean relative RMS error of the loads; log: the mean of its log",
    )
    f.add_argument(
        "--maxiter", type=int, default=200, help="L-BFGS-B iterations per start (default 200)"
    )
    f.add_argument(
        "--starts",
        type=int,
        default=1,
        help="starts: c = 0, then seeded random ones (default 1); the best is kept",
    )
    f.add_argument(
        "--seed", type=int, default=0, help="seed of the random starts (>= 0; default 0)"
    )
    f.add_argument(
        "--plane",
        choices=("stress", "strain"),
        default="stress",
        help="2-D meshes: plane stress/strain",
    )
    f.add_argument(
        "--format", default=None, help="mesh format if the file names do not tell (meshio name)"
    )


def _check(args):
    def bad(flag, msg, fix):
        raise SpringbenchError(msg, field=flag, fix=fix)

    for nu in args.nu:
        if not (-1 < nu < 0.5):
            bad("--nu", f"{nu} is out of range", "Poisson ratios in (-1, 0.5), e.g. --nu 0.3 0.45")
    if len(set(args.nu)) < len(args.nu):
        bad(
            "--nu",
            f"{' '.join(f'{v:g}' for v in args.nu)} repeats a value",
            "give each Poisson ratio once",
        )
    if args.maxiter < 1:
        bad(
            "--maxiter",
            f"{args.maxiter} is not a positive number of iterations",
            "e.g. --maxiter 200",
        )
    if not 1 <= args.starts <= 100:
        bad(
            "--starts",
            f"{args.starts} is not in 1..100",
            "e.g. --starts 1 (c = 0 only) or --starts 4",
        )
    if args.seed < 0:
        bad("--seed", f"{args.seed} is negative", "a seed >= 0, e.g. --seed 0")
    if args.out.suffix.lower() != ".json":
        bad("--out", f"'{args.out}' does not end in .json", "e.g. --out rule.json")
    from harness.outputs import check_out_file

    check_out_file(args.out, "--out")
    if len(set(p.resolve() for p in args.meshes)) < len(args.meshes):
        raise SpringbenchError(
            "is given twice",
            file=str(
                next(
                    p
                    for i, p in enumerate(args.meshes)
                    if p.resolve() in {q.resolve() for q in args.meshes[:i]}
                )
            ),
            fix="give each mesh once",
        )
    for p in args.meshes:
        if not p.is_file():
            raise SpringbenchError(
                "is a folder, not a mesh file" if p.is_dir() else "no such mesh file",
                file=str(p),
                fix="check the path",
            )


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
            raise SpringbenchError(
                f"has {', '.join(sorted(m.cells))} cells",
                file=str(p),
                fix=f"the learned rule is fitted on {SIMPLEX.get(m.dim, 'simplex')} meshes only "
                f"(quads and hexahedra use its scale alone)",
            )
        out.setdefault(m.dim, []).append((Path(p), m))
    return out


def main(args) -> int:
    _check(args)
    corpus = read_corpus(args.meshes, args.format)
    last = [0.0]

    def status(msg):  # at most one line in 5 s
        now = time.monotonic()
        if now - last[0] >= 5.0:
            last[0] = now
            print(f"  {msg}", file=sys.stderr, flush=True)

    t0 = time.monotonic()
    dims = {str(dim): _fit_dim(dim, meshes, args, status) for dim, meshes in sorted(corpus.items())}
    data = _record(args, corpus, dims, time.monotonic() - t0)
    from harness.outputs import atomic_write

    atomic_write(args.out, (json.dumps(data, indent=1) + "\n").encode(), "--out")
    print(f"-> {args.out}")
    return 0


def _fit_dim(dim: int, meshes, args, status) -> dict:
    """The learned rule's coefficients for one dimension: fitted on every mesh at every nu,
    with each sample's mean error before and after; printed as it is found."""
    from harness.models.learned_rule import FEATURES

    samples = []
    for path, m in meshes:
        for nu in args.nu:
            status(f"{dim}-D: {path.name} at nu = {nu:g}")
            samples.append(sample(path, nu, args.plane, args.format, mesh_obj=m))
    res = fit(samples, args.objective, args.maxiter, args.starts, args.seed, status=status)
    table = []
    for s in samples:
        before, after = errors(s, np.zeros(len(res.coefficients))), errors(s, res.coefficients)
        table.append(
            {
                "mesh": s.name,
                "nu": s.nu,
                "loads": len(s.loads),
                "mean_error_before": float(before.mean()),
                "mean_error_after": float(after.mean()),
            }
        )
    print(
        f"{dim}-D: {len(meshes)} meshes x {len(args.nu)} nu, objective ({args.objective}) "
        f"{res.before:.4g} (van Gelder, c = 0) -> {res.after:.4g}"
    )
    for name, c in zip(FEATURES[dim], res.coefficients):
        print(f"  c[{name}] = {c:+.4f}")
    return {
        "features": list(FEATURES[dim]),
        "coefficients": list(res.coefficients),
        "objective_before": res.before,
        "objective_after": res.after,
        "iterations": res.iterations,
        "evaluations": res.evaluations,
        "optimizer": res.message,
        "best_start": res.start,
        "samples": table,
    }


def _record(args, corpus, dims: dict, seconds: float) -> dict:
    """The rule file: the family, each dimension's fit, the corpus (with digests) and how
    the fit was run."""
    return {
        "rule": "learned",
        "family": "k = k_vangelder * exp(sum_j c_j phi_j) (harness/models/learned_rule.py)",
        "dims": dims,
        "corpus": [
            {
                "file": p.name,
                "sha256": _sha256(p),
                "dim": m.dim,
                "nodes": len(m.points),
                "cells": {k: len(v) for k, v in m.cells.items()},
            }
            for dim in sorted(corpus)
            for p, m in corpus[dim]
        ],
        "fit": {
            "command": "springbench " + " ".join(sys.argv[1:])
            if sys.argv[1:2] == ["rules"]
            else _command(args),
            "nu": list(args.nu),
            "objective": args.objective,
            "loads": "linear2d / linear3d states, exact closed forms at the nodes (no FEM)",
            "plane": args.plane,
            "maxiter": args.maxiter,
            "starts": args.starts,
            "seed": args.seed,
            "bound": BOUND,
            "seconds": round(seconds, 1),
        },
    }


def _command(args) -> str:
    """The command line that reproduces this fit (when not run from the shell)."""
    parts = [
        "springbench rules fit",
        *map(str, args.meshes),
        "--nu",
        *(f"{v:g}" for v in args.nu),
        "--objective",
        args.objective,
        "--maxiter",
        str(args.maxiter),
        "--starts",
        str(args.starts),
        "--seed",
        str(args.seed),
        "--out",
        str(args.out),
    ]
    return " ".join(parts)
