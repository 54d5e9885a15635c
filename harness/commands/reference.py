"""springbench reference CASE --points P.csv --out U.csv: FEM displacements at points."""

from __future__ import annotations

from pathlib import Path

HELP = "FEM reference displacements of a case at given points, one row per point and load case"


def add_arguments(p):
    p.add_argument("case", type=Path, help="case file (TOML)")
    p.add_argument("--points", type=Path, required=True, help="CSV with columns x,y[,z]")
    p.add_argument("--out", type=Path, required=True, help="CSV to write: load,x,y[,z],ux,uy[,uz]")
    p.add_argument("--full", action="store_true", help="use the case's [full] settings")
    p.add_argument(
        "--no-cache", action="store_true", help="recompute even if a cached solution exists"
    )


def main(args) -> int:
    import numpy as np
    import pandas as pd

    import reference
    from harness.case.reader import load_case
    from harness.errors import SpringbenchError
    from harness.outputs import atomic_write, check_out_file

    case = load_case(args.case, "full" if args.full else "quick")
    check_out_file(args.out, "--out")
    axes = "xyz"[: case.dim]
    header = f"a CSV file with a header line {','.join(axes)} and one point per row"

    def bad(msg, fix=header):
        return SpringbenchError(msg, file=str(args.points), field="--points", fix=fix)

    try:
        pts = pd.read_csv(args.points)
    except FileNotFoundError:
        raise bad("file not found", "check the path")
    except IsADirectoryError:
        raise bad("is a folder, not a CSV file")
    except pd.errors.EmptyDataError:
        raise bad("the file is empty")
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise bad(f"not a CSV file ({type(exc).__name__})")
    missing = [a for a in axes if a not in pts.columns]
    if missing:
        raise bad(f"missing column(s) {', '.join(missing)}")
    try:
        x = pts[list(axes)].to_numpy(float)
    except ValueError:
        raise bad("non-numeric coordinates", "numbers only")
    if not np.all(np.isfinite(x)):
        raise bad("missing or infinite coordinates", "a finite number in every column of every row")
    if len(x) == 0:
        raise bad("no points (a header line only)")
    sol = reference.solve(case, cache=not args.no_cache)
    frames = []
    for load in sol.loads:
        try:
            u = sol.displacement(x, load)
        except SpringbenchError as exc:  # e.g. points outside the body: this file's
            raise bad(exc.message, exc.fix) from None
        df = pd.DataFrame(x, columns=list(axes))
        df.insert(0, "load", load)
        for i, a in enumerate(axes):
            df["u" + a] = u[:, i]
        frames.append(df)
    out = pd.concat(frames, ignore_index=True)
    atomic_write(args.out, out.to_csv(index=False, float_format="%.17g").encode(), "--out")
    est = ", ".join(f"{k} {v:.1e}" for k, v in sol.error_estimate.items())
    print(f"{len(out)} rows -> {args.out} ({sol.n_dofs} dofs; estimates: {est})")
    return 0
