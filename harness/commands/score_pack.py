"""springbench score --displacements U DIR: the pack form of ``score`` (harness/commands/score.py
parses its flags; harness/export/pack_score.py computes the table)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from harness.errors import SpringbenchError


def _gates(args, names) -> dict:
    """{load: gate} from --max LOAD=X (each a load of the pack, X a number >= 0)."""
    out = {}
    for item in args.max_load:
        name, sep, value = item.partition("=")
        try:
            x = float(value)
        except ValueError:
            x = math.nan
        if not sep or not name or not (math.isfinite(x) and x >= 0):
            raise SpringbenchError(
                f"'{item}' is not LOAD=X with X a number >= 0",
                field="--max",
                fix="e.g. --max tip=0.05",
            )
        if name not in names:
            raise SpringbenchError(
                f"the pack has no load '{name}'", field="--max", fix=f"one of {', '.join(names)}"
            )
        out[name] = x
    return out


def _check_digest(answer, folder, pack) -> str:
    """Refuse an answer `engines run` made for another pack; the note to print when the
    answer carries no digest (an older springbench, or another writer), else ""."""
    from harness.export.pack import pack_digest
    from harness.export.pack_score import answer_digest

    theirs, ours = answer_digest(answer), pack_digest(pack)
    if theirs is not None and theirs != ours:
        raise SpringbenchError(
            f"made for the pack with digest {theirs}, but {folder} has digest {ours} "
            "(another mesh, clamp, load or material)",
            file=str(answer),
            fix=f"score it against the pack it was made for, or run the engine on {folder} "
            f"again: springbench engines run ENGINE {folder} --out U.npz",
        )
    return (
        f"springbench: {answer}: no pack digest in it (not written by this springbench's "
        "`engines run`): scored without checking it was made for this pack"
        if theirs is None
        else ""
    )


def model_run(answer) -> dict | None:
    """The record of the model `engines run --model` ran, from an answer (.npz), or None."""
    import json

    import numpy as np

    from harness.engines.tet_material import MODEL_KEY

    if Path(answer).suffix.lower() != ".npz":
        return None
    with np.load(answer) as z:
        return json.loads(str(z[MODEL_KEY])) if MODEL_KEY in z.files else None


def _scored_loads(args, names: list, fields: dict) -> tuple[list, str]:
    """The loads to score: those --loads names (each must be in the answer), else the
    pack's loads the answer has; and the note naming the others (an error with
    --require-all)."""
    from harness.export.pack import named_loads

    if args.loads is not None:
        wanted = named_loads(args.loads, names)
    else:
        wanted = names
    missing = [n for n in wanted if n not in fields]
    if missing and (args.require_all or args.loads is not None or len(missing) == len(wanted)):
        raise SpringbenchError(
            f"no displacements for load {missing[0]!r} ({len(missing)} of {len(wanted)} "
            f"missing: {', '.join(missing)})",
            file=str(args.displacements),
            fix=(
                "drop them from --loads, or give them"
                if args.loads is not None
                else "give every load of the pack, or drop --require-all to score those given"
                if args.require_all
                else f"give displacements for some of the pack's loads: {', '.join(names)}"
            ),
        )
    note = (
        f"springbench: {args.displacements}: no displacements for {len(missing)} of "
        f"{len(wanted)} loads, not scored: {', '.join(missing)} (--require-all makes this "
        "an error)"
        if missing
        else ""
    )
    return [n for n in wanted if n in fields], note


def main(args) -> int:
    from harness.export.pack import read_pack
    from harness.export.pack_score import _units, read_displacements

    _check_flags(args)
    pack = read_pack(args.model)
    names = [ld.name for ld in pack.loads]
    gates = _gates(args, names)
    fields = read_displacements(args.displacements, pack)
    note = _check_digest(args.displacements, args.model, pack)
    unknown = [n for n in fields if n not in names]
    if unknown:
        raise SpringbenchError(
            f"load {unknown[0]!r} is not in the pack",
            file=str(args.displacements),
            fix=f"the pack's loads: {', '.join(names)}",
        )
    wanted, missing_note = _scored_loads(args, names, fields)
    unscored = [n for n in gates if n not in wanted]
    if unscored:
        raise SpringbenchError(
            f"--max names '{unscored[0]}', which --loads leaves out",
            field="--max",
            fix="score it, or drop its gate",
        )
    _units(args.displacements, pack, {n: fields[n] for n in wanted})
    for line in (note, missing_note):
        if line:
            print(line, file=sys.stderr)
    return _report(args, pack, fields, wanted, gates)


def _check_flags(args) -> None:
    """The pack form's flags: one folder and an answer, no network flags, a gate >= 0, the
    outputs writable and not the answer."""
    from harness.outputs import check_out_file

    if args.displacements is None:
        raise SpringbenchError(
            "--max-g-norm, --max, --loads and --junit score a pack's displacements",
            field="--displacements",
            fix="springbench score --displacements U.npz DIR ...",
        )
    if args.model is None or args.case is not None:
        raise SpringbenchError(
            "the pack form takes one folder",
            field="DIR",
            fix="springbench score --displacements U.npz DIR",
        )
    if args.weights is not None or args.mode != "quick":
        raise SpringbenchError(
            "--weights and --full are for a network on a case",
            field="--weights",
            fix="drop them with --displacements (every node of a pack weighs alike)",
        )
    if args.max_g_norm is not None and not (
        math.isfinite(args.max_g_norm) and args.max_g_norm >= 0
    ):
        raise SpringbenchError(
            f"{args.max_g_norm} is not a number >= 0",
            field="--max-g-norm",
            fix="e.g. --max-g-norm 0.1 (a 10 % RMS error)",
        )
    for flag, out in (("--out", args.out), ("--junit", args.junit)):
        if out is not None:
            if Path(out).resolve() == Path(args.displacements).resolve():
                raise SpringbenchError(
                    f"{out} is an input of the command", field=flag, fix="write it elsewhere"
                )
            check_out_file(out, flag)


def _report(args, pack, fields: dict, wanted: list, gates: dict) -> int:
    """Score the wanted loads, print the table and the verdict, write --out and --junit;
    1 when a load misses its gate."""
    import pandas as pd

    from harness.engines.tet_material import describe
    from harness.export.pack_score import junit, score_fields
    from harness.outputs import atomic_write

    rows = score_fields(pack, fields, wanted, gates, args.max_g_norm)
    df = pd.DataFrame(rows)
    print(
        f"{args.model}: {pack.n_nodes} nodes, {len(wanted)} loads scored against the FEM "
        f"(E {pack.E:g} Pa, nu {pack.nu:g}); {args.displacements}"
    )
    ran = model_run(args.displacements)
    if ran is not None:
        print(f"the engine ran {describe(ran)}; masses: {ran.get('masses')}")
    print(
        df.drop(columns=[c for c in ("G_norm_mean",) if c in df]).to_string(
            index=False, float_format=lambda x: f"{x:.4g}"
        )
    )
    total = rows[-1]
    misses = [r["load"] for r in rows[:-1] if r["status"] == "miss"]
    print(
        f"pooled G_norm {total['G_norm']:.4g}, mean over loads {total['G_norm_mean']:.4g}"
        + (
            f"; {len(misses)} load(s) over the gate: {', '.join(misses)}"
            if misses
            else "; every load meets its gate"
            if gates or args.max_g_norm is not None
            else ""
        )
    )
    if args.out is not None:
        csv = df if ran is None else df.assign(model=ran["file"], model_sha256=ran["sha256"])
        atomic_write(args.out, csv.to_csv(index=False).encode(), "--out")
        print(f"-> {args.out}")
    if args.junit is not None:
        atomic_write(
            args.junit, junit(rows, f"springbench:{Path(args.model).resolve().name}"), "--junit"
        )
        print(f"-> {args.junit}")
    return 1 if misses else 0
