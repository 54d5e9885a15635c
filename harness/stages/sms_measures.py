"""Measures of the sms stage's models (harness/stages/sms.py): the per-load and held-out G
columns, the fitted loads' balanced score, natural frequencies against the FEM's
(``frequencies.csv``, ``freq_error_*``), and what an engine needs to know (``k_spread``,
``dt_stable``)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from harness.case.loadsets import family
from harness.errors import ModelError
from harness.export.engine import stable_step
from harness.mechanics.modal import frequencies
from harness.optimize.select import CLAMPED, training_score


def per_load_columns(sc, sh) -> dict:
    """G_<load> of every load, fitted and held out."""
    out = {f"G_{k}": v for k, v in sc.per_load.items()}
    if sh is not None:
        out.update({f"G_{k}": v for k, v in sh.per_load.items()})
    return out


def scored_columns(case, sc, sh, first=None) -> dict:
    """A scored row's G_<load> of every load, its G_fit_score and its held-out columns
    (``first``: an optimised row's start row, for the ``_initial`` ones)."""
    return {**per_load_columns(sc, sh), **fit_score(case, sc), **heldout_columns(sh, first)}


def families(case, names) -> list[str]:
    """Each fitted load's family: the linear sets' own, 'clamped' for every other load."""
    by_name = {l.name: l for l in case.loads}
    return [family(by_name[n]) or CLAMPED for n in names]


def fit_score(case, sc) -> dict:
    """``G_fit_score``: the validation's score of the row's model on the fitted loads as
    they are (harness/optimize/select.py ``training_score``: each load's own normalised G,
    families and clamped states weighted alike); ``G_rank_score``: the mean of the own
    normalised G of the fitted loads [loads] rank_by names, each as often as it is listed
    (NaN: none of them fitted)."""
    names = list(case.fit_loads)
    by = [sc.per_load_norm[n] for n in case.rank_by if n in case.fit_loads]
    return {
        "G_fit_score": training_score([sc.per_load_norm[n] for n in names], families(case, names)),
        "G_rank_score": float(np.mean(by)) if by else math.nan,
    }


def _finite(row, key) -> float:
    v = row.get(key, math.nan)
    return v if v is not None and math.isfinite(v) else math.inf


def rank(row) -> tuple:
    """Rows ranked as 'best' ranks rules (the fits start from the first, a refused fit
    exports it): by ``G_rank_score``, then ``G_fit_score``, then the pooled G. calibrate
    ranks by the end-swapped training states, the fitted loads most like the held-out
    ones (docs/calibrate.md, "Rules and the fit")."""
    return (
        _finite(row, "G_rank_score"),
        _finite(row, "G_fit_score"),
        row.get("G_norm_final", math.inf),
    )


def validation_rank(row) -> tuple:
    """Rules ranked by the validation loads' ``G_val_mean`` (harness/stages/sms_accept.py),
    then as :func:`rank` (a case without validation loads: as :func:`rank` alone)."""
    v = row.get("G_val_mean", math.nan)
    return (v if math.isfinite(v) else math.inf, *rank(row))


def heldout_columns(sh, first=None) -> dict:
    """On the held-out loads: G_heldout (pooled: normalised by all their displacements
    together), G_heldout_mean (the mean of each load's own normalised G, so a small load
    counts as much as a large one) and G_heldout_<load>; for an optimised row also the
    start's pooled and mean values (``_initial``); none without held-out loads."""
    if sh is None:
        return {}
    per = {f"G_heldout_{k}": float(v) for k, v in sh.per_load_norm.items()}
    out = {"G_heldout": sh.G_norm, "G_heldout_mean": float(np.mean(list(per.values()))), **per}
    if first is not None:
        out.update(
            G_heldout_initial=first.get("G_heldout", math.nan),
            G_heldout_mean_initial=first.get("G_heldout_mean", math.nan),
        )
    return out


def engine_columns(net, p1: bool) -> dict:
    """``k_spread`` (max / median spring constant; NaN for P1, which has none) and
    ``dt_stable`` (s, the symplectic Euler limit of the free, undamped model,
    harness.export.engine.stable_step; NaN without positive masses)."""
    k = np.asarray(net.k, float)
    out = {
        "k_spread": float(k.max() / np.median(k))
        if not p1 and len(k) and np.median(k) > 0
        else math.nan
    }
    try:
        out["dt_stable"] = stable_step(
            net.points, net.springs, net.k, net.masses, volume=getattr(net, "volume", None)
        )["dt_stable"]
    except ModelError:
        out["dt_stable"] = math.nan
    return out


def error_modes(opt, n_modes) -> int:
    """Modes in freq_error_*: the frequency term's count, else all computed ones."""
    fq = opt.get("frequency")
    return int(fq["modes"]) if fq else n_modes


def freq_error(f, f_fem, m) -> float:
    """RMS relative error of the first m natural frequencies against the FEM ones."""
    rel = np.asarray(f[:m], float) / np.asarray(f_fem[:m], float) - 1.0
    return float(np.sqrt(np.mean(rel**2))) if len(rel) and np.all(np.isfinite(rel)) else math.nan


def fem_frequencies(ref, n, load):
    """The reference's first n natural frequencies (Hz) with the constraints of ``load``,
    or None when it has none."""
    if ref is None or n <= 0:
        return None
    try:
        f = np.asarray(ref.frequencies(n, load=load), float)
    except Exception:  # noqa: BLE001 - the reference's modal solve is optional here
        return None
    return f if len(f) else None


def model_frequencies(case, ctx, fem_f, nets, n):
    """frequencies.csv: the first n SMS frequencies per model next to the FEM ones;
    returns {column: frequencies}: 'fem' and one per rule or optimised model."""
    if n <= 0:
        return {}
    cols = {"mode": np.arange(1, n + 1)}
    if fem_f is not None:
        cols["fem"] = np.pad(fem_f, (0, max(n - len(fem_f), 0)), constant_values=np.nan)[:n]
    for tag, net in nets.items():
        try:
            f = frequencies(net, case, n)
            cols[tag] = np.pad(f, (0, n - len(f)), constant_values=np.nan)[:n]
        except ModelError:
            continue
    if len(cols) > 1:
        pd.DataFrame(cols).to_csv(ctx.file("frequencies.csv"), index=False)
    return cols
