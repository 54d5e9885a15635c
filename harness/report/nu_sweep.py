"""The nu-sweep map (issue #15) from a suite's summary rows: per body, model class and
Poisson ratio the model's best scored row. A body is the case name without its ``_nu<x>``
suffix; a class's row is its optimised row if it has one (the fitted constants), else
its only row (``p1``, which has no constants)."""

from __future__ import annotations

import re

COLUMNS = ("G_norm_final", "G_heldout", "freq_error_final", "k_spread", "dt_stable")
CAUCHY_NU = {2: 1.0 / 3.0, 3: 0.25}     # central-force lattices: isotropic only here (2-D plane stress)


def sweep_frame(df):
    """One line per (body, model_class, nu): COLUMNS of that row, sorted; empty if the
    rows carry no ``model_class`` and ``nu``."""
    import pandas as pd
    need = {"case", "model_class", "nu", "G_norm_final"}
    if df.empty or not need <= set(df.columns):
        return pd.DataFrame()
    d = df.dropna(subset=["model_class", "nu", "G_norm_final"]).copy()
    if "status" in d:
        d = d[d["status"] != "error"]
    if "objective" in d:
        d = d[d["objective"].fillna("G") == "G"]
    if d.empty:
        return pd.DataFrame()
    d["body"] = [re.sub(r"_nu[0-9.]+$", "", str(c)) for c in d["case"]]
    d["fitted"] = d["optimizer"].fillna("none") != "none" if "optimizer" in d else False
    d = d.sort_values("fitted").groupby(["body", "model_class", "nu"], sort=False).tail(1)
    cols = ["body", "dim", "model_class", "nu"] + [c for c in COLUMNS if c in d]
    return d[[c for c in cols if c in d]].sort_values(["body", "model_class", "nu"]).reset_index(drop=True)


def sweep_table(frame):
    """G_norm (fitted) and G_heldout per body and nu, one column pair per model class."""
    import pandas as pd
    if frame.empty:
        return pd.DataFrame()
    wide = frame.pivot_table(index=["body", "nu"], columns="model_class",
                             values=[c for c in ("G_norm_final", "G_heldout") if c in frame])
    wide.columns = [f"{cls}: {'G_norm' if v == 'G_norm_final' else 'G_heldout'}" for v, cls in wide.columns]
    return wide[sorted(wide.columns)].reset_index()


def skipped_lines(df) -> list[str]:
    """One Markdown line per (body, model class) the sweep skipped, with its reason (a
    2-D body has no Bourguignon & Cani element: status "skip", ``note``)."""
    if df.empty or not {"case", "model_class", "status"} <= set(df.columns):
        return []
    d = df[df["status"] == "skip"]
    out = {}
    for case, cls, note in zip(d["case"], d["model_class"], d["note"] if "note" in d else [""] * len(d)):
        body = re.sub(r"_nu[0-9.]+$", "", str(case))
        out.setdefault((body, str(cls)), str(note) if isinstance(note, str) else "")
    return [f"- `{cls}` on `{body}`: skipped ({note or 'no reason given'})" for (body, cls), note in sorted(out.items())]
