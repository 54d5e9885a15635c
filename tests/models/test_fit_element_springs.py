"""stiffness_rules.fit_element_springs (batched pseudo-inverse) against a per-element
loop of numpy's lstsq written here, on random Delaunay tetrahedra, all six edges and
subsets of them (rank-deficient Gram matrices), with and without the non-negative fit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls
from scipy.spatial import Delaunay

from harness.case.elasticity import isotropic_compliance
from harness.models import stiffness_rules as sr


def _loop(Ke, points, c, pairs, nonneg):
    out = []
    for e in range(len(c)):
        bs = []
        for i, j in pairs:
            v = points[c[e, j]] - points[c[e, i]]
            v = v / np.linalg.norm(v)
            b = np.zeros(Ke.shape[1])
            b[3 * j : 3 * j + 3], b[3 * i : 3 * i + 3] = v, -v
            bs.append(b)
        A = np.stack([np.outer(b, b).ravel() for b in bs], 1)  # the Frobenius problem itself
        k = np.linalg.lstsq(A, Ke[e].ravel(), rcond=None)[0]
        if nonneg and k.min() < 0:
            k = nnls(A, Ke[e].ravel())[0]
        out.append(k)
    return np.array(out)


@pytest.mark.parametrize("n_pairs", [6, 5, 3, 1])
@pytest.mark.parametrize("nonneg", [False, True])
def test_batched_fit_matches_a_loop_of_lstsq(n_pairs, nonneg):
    rng = np.random.default_rng(n_pairs)
    p = rng.uniform(0, 1, (60, 3))
    t = Delaunay(p).simplices
    C = np.tile(np.linalg.inv(isotropic_compliance(1e5, 0.45)), (len(t), 1, 1))
    Ke = sr.fem_element_stiffness(p, t, "tetra", C)
    pairs = sr.element_pairs("tetra")[:n_pairs]
    k, mis = sr.fit_element_springs(Ke, p, t, pairs, nonneg)
    want = _loop(Ke, p, t, pairs, nonneg)
    np.testing.assert_allclose(k, want, rtol=0, atol=1e-9 * np.abs(want).max())
    B = _b(p, t, pairs)
    model = np.einsum("ms,msi,msj->mij", want, B, B)
    np.testing.assert_allclose(
        mis, np.linalg.norm(Ke - model, axis=(1, 2)) / np.linalg.norm(Ke, axis=(1, 2)), rtol=1e-9
    )


def _b(p, t, pairs):
    out = np.zeros((len(t), len(pairs), 12))
    for s, (i, j) in enumerate(pairs):
        v = p[t[:, j]] - p[t[:, i]]
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        out[:, s, 3 * j : 3 * j + 3], out[:, s, 3 * i : 3 * i + 3] = v, -v
    return out
