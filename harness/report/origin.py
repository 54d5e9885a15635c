"""Where a suite's numbers came from: the provenance of the runs that made its stored
results (harness/provenance.py), gathered into the suite folder's ``provenance.json`` and
shown per suite by the page and README.md. Results stored before provenance was recorded
count as "not recorded"."""

from __future__ import annotations

import json
from pathlib import Path

from harness.outputs import write_changed
from harness.provenance import ENGINE_VERSIONS, FIELDS, NOT_RECORDED, describe

FILE = "provenance.json"


def gather(manifests) -> dict:
    """{"runs": [{"provenance": {...}, "cases": [...]}, ...], "not_recorded": [cases]}: each
    distinct provenance (FIELDS, and ENGINE_VERSIONS where recorded) with the cases (and
    seeds) it made, most cases first; sorted, so the same results give the same file."""
    runs: dict[str, dict] = {}
    missing = []
    for m in manifests:
        label = str(m.get("case")) + (f" seed {m.get('seed')}" if m.get("n_seeds", 1) > 1 else "")
        p = m.get("provenance")
        if not isinstance(p, dict):
            missing.append(label)
            continue
        p = {k: p.get(k) for k in FIELDS} | (
            {ENGINE_VERSIONS: p[ENGINE_VERSIONS]} if ENGINE_VERSIONS in p else {}
        )
        runs.setdefault(json.dumps(p, sort_keys=True), {"provenance": p, "cases": []})[
            "cases"
        ].append(label)
    ordered = sorted(
        runs.values(), key=lambda r: (-len(r["cases"]), json.dumps(r["provenance"], sort_keys=True))
    )
    return {
        "runs": [{"provenance": r["provenance"], "cases": sorted(r["cases"])} for r in ordered],
        "not_recorded": sorted(missing),
    }


def write(suite_dir: Path, manifests) -> Path:
    """The suite folder's provenance.json (rewritten only when it changes)."""
    path = Path(suite_dir) / FILE
    write_changed(path, (json.dumps(gather(manifests), indent=1, sort_keys=True) + "\n").encode())
    return path


def lines(suite_dir: Path) -> list[str]:
    """One sentence per run that made the suite's results (with how many cases), and one
    for the cases whose provenance was not recorded."""
    try:
        data = json.loads((Path(suite_dir) / FILE).read_text())
    except (OSError, ValueError):
        return [f"{NOT_RECORDED}."]
    runs, missing = data.get("runs", []), data.get("not_recorded", [])
    total = sum(len(r.get("cases", [])) for r in runs) + len(missing)
    out = [
        f"{len(r.get('cases', []))} of {total} results: {describe(r.get('provenance'))}."
        for r in runs
    ]
    if missing:
        out.append(
            f"{len(missing)} of {total} results: {NOT_RECORDED} (stored before provenance "
            "was recorded)."
        )
    return out
