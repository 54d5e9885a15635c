"""springbench build CASE --out MODEL.vtu: write the spring/mass system a case describes."""

from __future__ import annotations

from pathlib import Path

HELP = "build the spring/mass system a case's [model] describes and write it as VTU (ParaView)"


def add_arguments(p):
    p.add_argument("case", metavar="CASE", help="case file with [model] kind = 'sms'")
    p.add_argument("--out", type=Path, required=True, metavar="MODEL.vtu", help="output VTU file")
    p.add_argument("--seed", type=int, default=0, help="added to [model] seed (default 0)")
    p.add_argument(
        "--stiffness", default=None, help="stiffness rule (default: the first of [model] stiffness)"
    )
    p.add_argument(
        "--full",
        dest="mode",
        action="store_const",
        const="full",
        default="quick",
        help="use the case's [full] table",
    )
    p.add_argument(
        "--displacements",
        action="store_true",
        help="also solve the load cases and store u_<load> point data",
    )


def check_stiffness(rule: str | None) -> None:
    """--stiffness names a stiffness rule (None: the case's own)."""
    from harness.errors import SpringbenchError
    from harness.registry import STIFFNESS_RULES

    if rule is not None and rule not in STIFFNESS_RULES:
        raise SpringbenchError(
            f"unknown stiffness rule '{rule}'",
            field="--stiffness",
            fix=f"one of {', '.join(STIFFNESS_RULES)}, e.g. --stiffness deussen",
        )


def main(args) -> int:
    from harness.case.reader import load_case
    from harness.errors import CaseError, SpringbenchError
    from harness.export.vtu import write_vtu
    from harness.models.sms import build_network
    from harness.outputs import check_out_file

    case = load_case(args.case, args.mode)
    check_out_file(args.out, "--out")
    check_stiffness(args.stiffness)
    if args.seed < 0:
        raise SpringbenchError(
            f"{args.seed} is negative", field="--seed", fix="a seed >= 0, e.g. --seed 0"
        )
    sec = case.section("model")
    if sec is None or sec.get("kind") != "sms":
        raise CaseError(
            "no [model] with kind = 'sms'",
            file=str(args.case),
            field="model.kind",
            fix="add [model] kind = 'sms' with placement, grid/n_points, structure",
        )
    net = build_network(case, seed=args.seed, stiffness=args.stiffness)
    disp = None
    if args.displacements:
        from harness.mechanics import statics

        res = statics.solve(net, case)
        disp = dict(zip(res.names, res.u))
    try:
        write_vtu(args.out, net, disp)
    except SpringbenchError as exc:  # the file system refused after the check: name the flag
        raise SpringbenchError(
            exc.message, file=exc.file, field=exc.field or "--out", fix=exc.fix
        ) from None
    i = net.info
    print(
        f"{case.name}: {net.n_nodes} nodes, {net.n_springs} springs, stiffness '{i['stiffness']}', "
        f"masses '{i['masses']}' (moment residual {i['mass_residual']:.2e}, "
        f"{i['negative_masses']} negative), "
        f"seed {i['seed']} -> {args.out}"
    )
    return 0
