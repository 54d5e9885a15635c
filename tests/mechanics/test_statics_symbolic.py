"""harness.mechanics.statics reuses the multifrontal Cholesky's symbolic factorisation
across networks of one pattern (the stiffness rules of a calibration): every solve still
matches scipy's spsolve (independent), the Symbolic is built once per pattern, and a
different constraint set (another pattern) gets its own."""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from harness.geometry import grid_points
from harness.linalg import multifrontal
from harness.mechanics import statics
from harness.models.springs import incidence, stiffness_matrix
from harness.models.topology import grid_structure


def test_symbolic_is_shared_by_networks_of_one_pattern(monkeypatch):
    monkeypatch.setattr(statics, "_SYMBOLIC", {})
    monkeypatch.setattr(statics, "MULTIFRONTAL_MIN", 100)
    built = []
    real = multifrontal.Symbolic

    def counting(*a, **k):
        built.append(1)
        return real(*a, **k)

    monkeypatch.setattr(statics, "Symbolic", counting)  # where statics looks it up
    shape = (5, 5, 8)
    pts = grid_points(np.zeros(3), np.array([1.0, 1.0, 2.0]), shape)
    top = grid_structure(shape, "edges+face+body")
    rng = np.random.default_rng(0)
    f = rng.normal(size=pts.size)
    for clamp, expected in ((shape[0] * shape[1], 1), (2 * shape[0] * shape[1], 2)):
        free = np.ones(pts.size, bool)
        free[: 3 * clamp] = False
        for _ in range(3):  # three rules' constants
            k = np.exp(rng.normal(0, 0.5, len(top.springs)))
            u = statics.solve_arrays(pts, top.springs, k, free, f)
            K = stiffness_matrix(incidence(pts, top.springs), k).tocsc()
            fd = np.flatnonzero(free)
            want = spla.spsolve(K[fd][:, fd], f[fd])
            np.testing.assert_allclose(u[fd], want, rtol=0, atol=1e-9 * np.abs(want).max())
        assert len(built) == expected
