"""springbench reference CASE --points P.csv --out U.csv: FEM displacements at points."""

from __future__ import annotations

from pathlib import Path

HELP = "FEM reference displacements of a case at given points, one row per point and load case"


def add_arguments(p):
    p.add_argument("case", type=Path, help="case file (TOML)")
    p.add_argument("--points", type=Path, required=True, help="CSV with columns x,y[,z]")
    p.add_argument("--out", type=Path, required=True, help="CSV to write: load,x,y[,z],ux,uy[,uz]")
    p.add_argument("--full", action="store_true", help="use the case's [full] settings")
    p.add_argument("--no-cache", action="store_true", help="recompute even if a cached solution exists")


def main(args) -> int:
    import numpy as np
    import pandas as pd

    import reference
    from harness.cases import load_case
    from harness.errors import SpringbenchError
    case = load_case(args.case, "full" if args.full else "quick")
    axes = "xyz"[: case.dim]
    try:
        pts = pd.read_csv(args.points)
    except FileNotFoundError:
        raise SpringbenchError("file not found", file=str(args.points), fix="check the path")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise SpringbenchError(f"not a CSV file ({type(exc).__name__})", file=str(args.points))
    missing = [a for a in axes if a not in pts.columns]
    if missing:
        raise SpringbenchError(f"missing column(s) {', '.join(missing)}", file=str(args.points),
                               fix=f"give a header line {','.join(axes)}")
    try:
        x = pts[list(axes)].to_numpy(float)
    except ValueError:
        raise SpringbenchError("non-numeric coordinates", file=str(args.points), fix="numbers only")
    if not np.all(np.isfinite(x)):
        raise SpringbenchError("missing or infinite coordinates", file=str(args.points))
    sol = reference.solve(case, cache=not args.no_cache)
    frames = []
    for load in sol.loads:
        u = sol.displacement(x, load)
        df = pd.DataFrame(x, columns=list(axes))
        df.insert(0, "load", load)
        for i, a in enumerate(axes):
            df["u" + a] = u[:, i]
        frames.append(df)
    out = pd.concat(frames, ignore_index=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    out.to_csv(args.out, index=False, float_format="%.17g")
    est = ", ".join(f"{k} {v:.1e}" for k, v in sol.error_estimate.items())
    print(f"{len(out)} rows -> {args.out} ({sol.n_dofs} dofs; estimates: {est})")
    return 0
