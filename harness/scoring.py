"""The G criteria of Deussen, Kobbelt & Tuecke 1995 (eq. 12, Section 5.4), as DESIGN.md:

    G_{a:b:c} = sqrt( sum_i sum_p w_p |u_ref,i(p) - u_i(p)|^2 ),  w_p = a inner, b border, c corner

G_s = G_{1:1:1}. The normalised G divides by sqrt(sum_i sum_p w_p |u_ref,i(p)|^2) (the G of
a model that does not move), so it is dimensionless and comparable across cases. The
per-load values G_i satisfy G^2 = sum_i G_i^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

import numpy as np


@dataclass(frozen=True)
class ScoreResult:
    """G with ``weights`` (a, b, c), G_s, the normalised G, and per-load breakdowns."""
    G: float
    G_s: float
    G_norm: float
    weights: tuple[float, float, float]
    per_load: Mapping[str, float]
    per_load_norm: Mapping[str, float]
    n_nodes: int

    def rows(self) -> list[dict]:
        """One row per load case plus a 'total' row (for CSV output)."""
        out = [{"load": k, "G": v, "G_norm": self.per_load_norm[k]} for k, v in self.per_load.items()]
        out.append({"load": "total", "G": self.G, "G_norm": self.G_norm})
        return out


def node_weights(classes: np.ndarray, weights) -> np.ndarray:
    """w_p (n,) from node classes (0 inner, 1 border, 2 corner) and (a, b, c)."""
    return np.asarray(weights, float)[np.asarray(classes, int)]


def g_arrays(u_ref: np.ndarray, u: np.ndarray, classes: np.ndarray, weights, names=None) -> ScoreResult:
    """Scores from plain arrays: u_ref, u (L, n, dim), classes (n,), weights (a, b, c)."""
    u_ref = np.asarray(u_ref, float)
    u = np.asarray(u, float)
    if u_ref.shape != u.shape or u.ndim != 3:
        raise ValueError(f"u_ref {u_ref.shape} and u {u.shape} must both be (loads, nodes, dim)")
    names = list(names) if names is not None else [f"load{i}" for i in range(len(u))]
    weights = tuple(float(x) for x in weights)

    def per(w):
        err = np.einsum("p,lpd->l", w, (u_ref - u) ** 2)
        ref = np.einsum("p,lpd->l", w, u_ref ** 2)
        return err, ref
    w = node_weights(classes, weights)
    err, ref = per(w)
    err_s, ref_s = per(np.ones(len(w)))
    G = float(np.sqrt(err.sum()))
    with np.errstate(divide="ignore", invalid="ignore"):
        per_norm = np.sqrt(err / ref)
        G_norm = float(np.sqrt(err.sum() / ref.sum())) if ref.sum() > 0 else float("nan")
    return ScoreResult(G, float(np.sqrt(err_s.sum())), G_norm, weights,
                       MappingProxyType(dict(zip(names, np.sqrt(err).tolist()))),
                       MappingProxyType(dict(zip(names, per_norm.tolist()))), u.shape[1])


def reference_displacements(ref, points: np.ndarray, names) -> np.ndarray:
    """(L, n, dim): the reference sampled at the node positions."""
    return np.array([ref.displacement(points, name) for name in names])


def case_weights(case, weights=None) -> tuple[float, float, float]:
    if weights is not None:
        return tuple(float(x) for x in weights)
    sec = case.section("score")
    return tuple(sec["weights"]) if sec is not None else (1.0, 1.0, 1.0)


def score(network, case, ref, weights=None, statics=None) -> ScoreResult:
    """G of a spring network on a case against a ``ReferenceSolution`` (``weights``
    default to the case's [score] weights). ``statics``: an already solved
    ``harness.statics.StaticsResult`` to reuse."""
    from harness import statics as st
    res = statics or st.solve(network, case)
    u_ref = reference_displacements(ref, network.points, res.names)
    return g_arrays(u_ref, res.u, network.classes, case_weights(case, weights), res.names)
