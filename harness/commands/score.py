"""springbench score MODEL.vtu CASE: G criteria of any spring network against the FEM reference;
springbench score --displacements U DIR: any engine's displacements on a benchmark pack
(harness/export/pack_score.py), with a gate for CI (exit 1 on a miss, a JUnit report)."""

from __future__ import annotations

from pathlib import Path

HELP = (
    "score a spring network (VTU: points, line cells, cell data 'stiffness') on a case: G "
    "per load, G_{a:b:c}, "
    "normalised G, and G_ref (the reference's own error as a normalised G); or, with "
    "--displacements, any "
    "engine's displacements on a benchmark pack (springbench pack), gated for CI"
)
EPILOG = """forms:
  springbench score MODEL.vtu CASE [--out G.csv] [--weights A B C] [--full]
  springbench score --displacements U.npz|U.csv|U.vtu DIR [--max-g-norm X] [--max LOAD=X ...]
                    [--loads A,B] [--out G.csv] [--junit FILE]
the pack form prints per load G_norm (RMS error / RMS FEM displacement), max_error (largest
error / largest FEM displacement), G_ref (the FEM's own error estimate as a G_norm), the gate and
status (ok / ref-coarse / miss); exit 1 when a load misses its gate, 0 when all meet it, 2 for bad
input. U: .npz one (n, dim) array per load name; .csv columns load,node,ux,uy[,uz]; .vtu point
data u_<load>; at the pack's nodes, in metres. The loads U has are scored, the missing ones
named (--require-all: an error); U from `engines run` carries the pack's digest, and one made
for another pack is refused."""


def add_arguments(p):
    p.add_argument(
        "model",
        metavar="MODEL.vtu|DIR",
        nargs="?",
        help="spring network (e.g. from 'springbench build'); with --displacements: the "
        "pack's folder",
    )
    p.add_argument(
        "case", metavar="CASE", nargs="?", help="case file (body, material, loads, [score] weights)"
    )
    p.add_argument(
        "--displacements",
        type=Path,
        default=None,
        metavar="U",
        help="an engine's displacements per load of a pack (.npz, .csv or .vtu; metres)",
    )
    p.add_argument(
        "--max-g-norm",
        dest="max_g_norm",
        type=float,
        default=None,
        metavar="X",
        help="pack form: exit 1 when a load's G_norm exceeds X",
    )
    p.add_argument(
        "--max",
        dest="max_load",
        action="append",
        default=[],
        metavar="LOAD=X",
        help="pack form: this load's own gate (repeatable)",
    )
    p.add_argument(
        "--loads",
        default=None,
        metavar="A,B",
        help="pack form: score only these loads (default: every load the answer has)",
    )
    p.add_argument(
        "--require-all",
        dest="require_all",
        action="store_true",
        help="pack form: an answer without every load of the pack is an error (default: "
        "score the loads it has and name the missing ones)",
    )
    p.add_argument(
        "--junit",
        type=Path,
        default=None,
        metavar="FILE",
        help="pack form: also write a JUnit XML report (one test case per load)",
    )
    p.add_argument(
        "--out", type=Path, default=None, metavar="CSV", help="also write the table as CSV"
    )
    p.add_argument(
        "--weights",
        type=float,
        nargs=3,
        default=None,
        metavar=("A", "B", "C"),
        help="G weights inner border corner (default: the case's [score] weights)",
    )
    p.add_argument(
        "--full",
        dest="mode",
        action="store_const",
        const="full",
        default="quick",
        help="use the case's [full] table",
    )


def score_table(net, case, ref, weights=None):
    """(DataFrame: one row per load case and a total row, the ScoreResult, the row's
    ``ref_status``: "ok" or "ref-coarse", decided at the network's own nodes)."""
    import pandas as pd

    from harness.mechanics import statics
    from harness.scoring import (
        case_weights,
        g_arrays,
        g_ref_arrays,
        met_tol_here,
        ref_status,
        reference_displacements,
        reference_error,
    )

    w = case_weights(case, weights)
    res = statics.solve(net, case)
    u_ref = reference_displacements(ref, net.points, res.names)
    sc = g_arrays(u_ref, res.u, net.classes, w, res.names)
    s1 = g_arrays(u_ref, res.u, net.classes, (1, 1, 1), res.names)
    e = reference_error(ref, net.points, res.names)
    g_ref, g_ref_load = g_ref_arrays(u_ref, e, net.classes, w)
    label = ":".join(f"{x:g}" for x in w)
    rows = [
        {
            "load": n,
            "G_s": s1.per_load[n],
            f"G_{label}": sc.per_load[n],
            "G_norm": sc.per_load_norm[n],
            "G_ref": float(g),
        }
        for n, g in zip(res.names, g_ref_load)
    ]
    rows.append(
        {"load": "total", "G_s": sc.G_s, f"G_{label}": sc.G, "G_norm": sc.G_norm, "G_ref": g_ref}
    )
    return pd.DataFrame(rows), sc, ref_status(g_ref, sc.G_norm, met_tol_here(ref, u_ref, e))


def _cell_data_mismatch(path) -> tuple | None:
    """(field, values, cells) of the first cell-data array of a VTU whose length is not
    its cell block's, or None (meshio's VTU reader, before its own check)."""
    from xml.etree.ElementTree import ParseError

    from meshio import ReadError
    from meshio.vtu._vtu import VtuReader

    if Path(path).suffix.lower() != ".vtu":
        return None
    try:
        r = VtuReader(str(path))
    except (OSError, ReadError, ValueError, KeyError, ParseError):  # not a VTU it reads: the
        return None  # caller's reader then raises its own one-line error
    for name, arrays in r.cell_data.items():
        for block, data in zip(r.cells, arrays):
            if len(data) != len(block.data):
                return name, len(data), len(block.data), block.type
    return None


def read_network(path):
    """The network of a VTU (harness.export.vtu.read_vtu); a cell-data array of the wrong
    length is named with its field and counts."""
    from harness.errors import SpringbenchError
    from harness.export.vtu import read_vtu

    try:
        return read_vtu(path)[0]
    except SpringbenchError:
        bad = _cell_data_mismatch(path)
        if bad is None:
            raise
        name, n, m, kind = bad
        raise SpringbenchError(
            f"{n} values for {m} '{kind}' cells" + (" (springs)" if kind == "line" else ""),
            file=str(path),
            field=name,
            fix=f"one '{name}' value per cell: write the network again with springbench build",
        ) from None


def main(args) -> int:
    if (
        args.displacements is not None
        or args.max_g_norm is not None
        or args.max_load
        or args.junit is not None
        or args.loads is not None
        or args.require_all
    ):
        from harness.commands.score_pack import main as pack_main

        return pack_main(args)
    from harness.errors import SpringbenchError

    if args.model is None or args.case is None:
        raise SpringbenchError(
            "needs MODEL.vtu and CASE (or --displacements U DIR for a pack)",
            fix="springbench score MODEL.vtu CASE, or springbench score --displacements U.npz DIR",
        )
    _check_weights(args.weights)
    _check_paths(args)
    net, case = _inputs(args)
    _report(args, net, case)
    return 0


def _check_weights(weights) -> None:
    """--weights: three finite numbers >= 0, not all zero, each 0 or computable."""
    import math

    from harness.case.schema import LARGEST, SMALLEST
    from harness.errors import SpringbenchError

    if weights is None:
        return
    said = " ".join(f"{w:g}" for w in weights)
    if not (all(math.isfinite(w) and w >= 0 for w in weights) and sum(weights) > 0):
        raise SpringbenchError(
            f"{said} are not three finite weights >= 0, not all zero",
            field="--weights",
            fix="e.g. --weights 1 3 15",
        )
    if not all(w == 0 or SMALLEST <= w <= LARGEST for w in weights):
        raise SpringbenchError(
            f"{said}: a weight is too {'large' if max(weights) > LARGEST else 'small'} to "
            "compute with",
            field="--weights",
            fix=f"weights between {SMALLEST:g} and {LARGEST:g} (or 0), e.g. --weights 1 3 15",
        )


def _check_paths(args) -> None:
    """The inputs are files and --out is none of them."""
    from harness.errors import SpringbenchError

    for what, path in (("network", args.model), ("case", args.case)):
        if Path(path).is_dir():
            raise SpringbenchError(
                f"cannot read it: a folder, not a {what} file",
                file=str(path),
                fix="give the file's path",
            )
    if args.out is not None and any(
        Path(args.out).resolve() == Path(f).resolve() for f in (args.model, args.case)
    ):
        raise SpringbenchError(
            f"{args.out} is an input of the command: the table would overwrite it",
            field="--out",
            fix="give another file name, e.g. --out score.csv",
        )


def _inputs(args):
    """(network, case): read, --out checked writable, the dimensions matched, the node
    classes by the case's body when it is not a mesh (whoever wrote the file)."""
    import dataclasses

    from harness.case.reader import load_case
    from harness.errors import ModelError
    from harness.geometry import body_geometry
    from harness.models.sms import node_classes

    case = load_case(args.case, args.mode)
    if args.out:
        from harness.outputs import check_out_file

        check_out_file(args.out, "--out")
    net = read_network(args.model)
    if net.dim != case.dim:
        raise ModelError(
            f"the network is {net.dim}-D but the case is {case.dim}-D",
            file=str(args.model),
            fix="score it on a case of the same dimension",
        )
    body = body_geometry(case)
    if body.kind != "mesh":
        net = dataclasses.replace(net, classes=node_classes(net.points, body))
    return net, case


def _report(args, net, case) -> None:
    """Score the network against the case's reference; print the table (and write it)."""
    import reference
    from harness.errors import ModelError

    ref = reference.solve(case)
    try:
        df, sc, status = score_table(net, case, ref, args.weights)
    except ModelError as exc:  # the network cannot carry the case's loads: the model file's fault
        raise ModelError(exc.message, file=str(args.model), fix=exc.fix) from None
    print(
        f"{case.name}: {net.n_nodes} nodes, {net.n_springs} springs, weights "
        f"{':'.join(f'{x:g}' for x in sc.weights)}"
    )
    print(df.to_string(index=False, float_format=lambda x: f"{x:.6g}"))
    if status != "ok":
        print(
            "ref-coarse: the reference's own error (G_ref, normalised like G_norm) is above "
            "10 % of G_norm, or it missed its tol at these nodes; G says as much about the "
            "reference as about the model"
        )
    if args.out:
        from harness.outputs import atomic_write

        atomic_write(args.out, df.to_csv(index=False).encode(), "--out")
        print(f"-> {args.out}")
