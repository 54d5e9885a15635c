"""What any engine computed on a benchmark pack, scored against the pack's FEM
(``springbench score --displacements U DIR``).

Per load, over the pack's nodes (every node weighs alike):

- ``G_norm`` = sqrt(sum |u - u_fem|^2 / sum |u_fem|^2), the RMS displacement error
  relative to the FEM's RMS displacement (G_{1:1:1} normalised, Deussen 1995 eq. 12);
- ``max_error`` = max |u - u_fem| / max |u_fem|;
- ``G_ref`` = sqrt(sum e^2 / sum |u_fem|^2) with e the FEM's own error estimate at each
  node: the same measure for the FEM against the truth (NaN where it has none);
- ``status``: "miss" above the gate (``--max-g-norm``, ``--max LOAD=X``), else
  "ref-coarse" when G_ref exceeds a tenth of G_norm (part of the G is the FEM's), else "ok".

The total row pools every scored load (``G_norm`` over all of them together) and gives the
mean of the loads' own G_norm (``G_norm_mean``).
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from harness.errors import SpringbenchError
from harness.export.pack import DIGEST_KEY
from harness.scoring import g_arrays, g_ref_arrays, ref_status

# u / u_fem near these: the engine's length unit is not m
UNIT_FACTORS = {1e3: "mm", 1e2: "cm", 1e-3: "km"}


def _bad(message, file, fix, field=None):
    raise SpringbenchError(message, file=str(file), field=field, fix=fix)


def read_displacements(path, pack) -> dict:
    """{load: (n, dim) displacements} from an .npz (one array per load), a .csv (columns
    load, node, ux, uy[, uz]) or a .vtu (point data u_<load>), checked against the pack."""
    path = Path(path)
    if not path.is_file():
        _bad("no such file", path, "give the engine's displacements (.npz, .csv or .vtu)")
    ext = path.suffix.lower()
    n, dim = pack.n_nodes, pack.dim
    try:
        if ext == ".npz":
            with np.load(path) as z:
                # "__" keys are records (DIGEST_KEY, the model run), not loads
                out = {k: np.asarray(z[k], float) for k in z.files if not k.startswith("__")}
        elif ext == ".csv":
            import pandas as pd

            df = pd.read_csv(path)
            cols = ["ux", "uy", "uz"][:dim]
            missing = [c for c in ["load", "node", *cols] if c not in df.columns]
            if missing:
                _bad(f"no column {', '.join(missing)}", path, f"columns load,node,{','.join(cols)}")
            out = {}
            for name, g in df.groupby("load", sort=False):
                u = np.full((n, dim), np.nan)
                nodes = g["node"].to_numpy()
                if len(g) != n or nodes.min() < 0 or nodes.max() >= n or len(np.unique(nodes)) != n:
                    _bad(
                        f"load {name!r} has {len(g)} rows for nodes "
                        f"{nodes.min()}..{nodes.max()}; the pack has {n} "
                        f"nodes",
                        path,
                        f"one row per node 0..{n - 1} and load",
                    )
                u[nodes] = g[cols].to_numpy(float)
                out[str(name)] = u
        elif ext == ".vtu":
            import meshio

            m = meshio.read(path)
            out = {
                k[2:]: np.asarray(v, float) for k, v in m.point_data.items() if k.startswith("u_")
            }
        else:
            _bad(f"'{ext}' is not a displacement format", path, "give .npz, .csv or .vtu")
    except SpringbenchError:
        raise
    except Exception as exc:  # noqa: BLE001 - any unreadable file is the user's file's fault
        _bad(
            f"unreadable ({type(exc).__name__}: {exc})", path, "write it again (.npz, .csv or .vtu)"
        )
    for name, u in out.items():
        if u.ndim == 2 and u.shape[1] == 3 and dim == 2:
            out[name] = u = u[:, :2]
        if u.shape != (n, dim):
            _bad(
                f"load {name!r} has shape {u.shape}; the pack has {n} nodes in {dim}-D",
                path,
                f"one ({n}, {dim}) field per load, at the pack's nodes in its order",
            )
        if not np.all(np.isfinite(u)):
            _bad(
                f"load {name!r} holds NaN or infinite values (the engine diverged or did "
                "not settle?)",
                path,
                "a finite displacement at every node",
            )
    return out


def answer_digest(path) -> str | None:
    """The pack digest `engines run` wrote into an answer (.npz), or None (none there)."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        return None
    with np.load(path) as z:
        return str(z[DIGEST_KEY]) if DIGEST_KEY in z.files else None


def _units(path, pack, fields: dict) -> None:
    """One line when every load's displacements are off the FEM's by a unit's factor."""
    ratios = []
    for ld in pack.loads:
        if ld.name in fields:
            ref = float(np.linalg.norm(ld.u_fem))
            if ref > 0:
                ratios.append(float(np.linalg.norm(fields[ld.name])) / ref)
    if len(ratios) and all(r > 0 for r in ratios):
        typical = float(np.exp(np.median(np.log(ratios))))
        for factor, unit in UNIT_FACTORS.items():
            if abs(math.log10(typical / factor)) < 0.3:
                _bad(
                    f"the displacements are ~{typical:.3g}x the FEM's: in {unit}, not m?",
                    path,
                    f"give metres (divide by {factor:g})"
                    if factor > 1
                    else f"give metres (times {1 / factor:g})",
                )


def score_fields(
    pack, fields: dict, loads=None, limits: dict | None = None, max_g_norm: float | None = None
) -> list:
    """Rows (dicts) per scored load and a total row; ``limits`` {load: gate}, ``max_g_norm``
    the gate of the others (None: none). G_norm and G_ref are harness.scoring's with every
    node weighing alike."""
    limits = dict(limits or {})
    names = list(loads) if loads is not None else [ld.name for ld in pack.loads]
    u_fem = np.stack([pack.load(n).u_fem for n in names])
    u = np.stack([fields[n] for n in names])
    classes, ones = np.zeros(pack.n_nodes, int), (1.0, 1.0, 1.0)
    scores = g_arrays(u_fem, u, classes, ones, names)
    _, g_ref = g_ref_arrays(
        u_fem, np.stack([pack.load(n).u_fem_error for n in names]), classes, ones
    )
    rows = []
    for i, name in enumerate(names):
        g = float(scores.per_load_norm[name])
        umax = float(np.linalg.norm(u_fem[i], axis=1).max())
        gate = limits.get(name, max_g_norm)
        rows.append(
            {
                "load": name,
                "role": pack.load(name).role,
                "G_norm": g,
                "max_error": float(np.linalg.norm(u[i] - u_fem[i], axis=1).max()) / umax
                if umax > 0
                else math.nan,
                "G_ref": float(g_ref[i]),
                "gate": math.nan if gate is None else float(gate),
                "status": "miss"
                if gate is not None and g > gate
                else ref_status(float(g_ref[i]), g, None),
            }
        )
    rows.append(
        {
            "load": "total",
            "role": "",
            "G_norm": scores.G_norm,
            "max_error": max((r["max_error"] for r in rows), default=math.nan),
            "G_ref": math.nan,
            "gate": math.nan,
            "status": "miss" if any(r["status"] == "miss" for r in rows) else "ok",
            "G_norm_mean": float(np.mean([r["G_norm"] for r in rows])) if rows else math.nan,
        }
    )
    return rows


def junit(rows, suite: str) -> bytes:
    """A JUnit XML report: one <testcase> per load, a <failure> where the gate missed."""
    cases = [r for r in rows if r["load"] != "total"]
    ts = ET.Element(
        "testsuite",
        name=suite,
        tests=str(len(cases)),
        failures=str(sum(r["status"] == "miss" for r in cases)),
        errors="0",
        skipped="0",
        time="0",
    )
    for r in cases:
        tc = ET.SubElement(ts, "testcase", classname=suite, name=r["load"], time="0")
        text = (
            f"G_norm {r['G_norm']:.6g} (gate {r['gate']:.6g}), max_error {r['max_error']:.6g}, "
            f"G_ref {r['G_ref']:.3g}"
        )
        if r["status"] == "miss":
            ET.SubElement(
                tc, "failure", message=f"G_norm {r['G_norm']:.4g} > {r['gate']:.4g}", type="gate"
            ).text = text
        else:
            ET.SubElement(tc, "system-out").text = text
    suites = ET.Element("testsuites")
    suites.append(ts)
    return (
        b'<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(suites, encoding="utf-8") + b"\n"
    )
