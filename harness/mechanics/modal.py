"""Natural frequencies of a spring network: (K - lambda M) u = 0 with M = diag(masses)
(Deussen 1995 eq. 13), constrained like a load case (default: the case's first one), in
Hz (sqrt(lambda) / 2 pi) like ``ReferenceSolution.frequencies``."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp
from scipy.sparse.linalg import eigsh

from harness.errors import ModelError
from harness.models.springs import incidence, stiffness_matrix


def frequencies_arrays(points, springs, k, masses, free: np.ndarray, n_modes: int = 6) -> np.ndarray:
    """First ``n_modes`` frequencies (Hz) on the free dofs (plain arrays)."""
    masses = np.asarray(masses, float)
    if np.any(masses <= 0):
        raise ModelError(f"{int(np.sum(masses <= 0))} nodes have masses <= 0, so M is not positive definite",
                         field="model.masses", fix="use masses = 'moments-nonneg', 'voronoi' or 'uniform'")
    K = stiffness_matrix(incidence(points, springs), k)
    return matrix_frequencies(K, masses, free, n_modes)


def matrix_frequencies(K, masses, free: np.ndarray, n_modes: int = 6) -> np.ndarray:
    """First ``n_modes`` frequencies (Hz) of a stiffness matrix K (ndof, ndof) with the
    node masses (n,) on the free dofs (also the linearised Bourguignon-Cani models)."""
    masses = np.asarray(masses, float)
    dim = K.shape[0] // len(masses)
    fd = np.flatnonzero(np.asarray(free, bool))
    Kf = sp.csr_matrix(K)[fd][:, fd]
    m = np.repeat(masses, dim)[fd]
    n_modes = min(n_modes, len(fd))
    if len(fd) <= 1500:
        # symmetric scaling by M^-1/2 turns it into a standard problem
        s = 1 / np.sqrt(m)
        lam = sl.eigh((Kf.toarray() * s[:, None]) * s[None, :], eigvals_only=True,
                      subset_by_index=[0, n_modes - 1])
    else:
        lam = eigsh(Kf.tocsc(), k=n_modes, M=sp.diags(m).tocsc(), sigma=0.0, which="LM",
                    return_eigenvectors=False,
                    v0=np.random.default_rng(0).standard_normal(Kf.shape[0]))  # seeded: same bits every run
    return np.sqrt(np.maximum(np.sort(lam), 0)) / (2 * np.pi)


def frequencies(network, case, n_modes: int = 6, load: str | None = None) -> np.ndarray:
    """First ``n_modes`` natural frequencies (Hz) with the constraints of load ``load``
    (default: harness.case.loads.modal_load)."""
    from harness.case.loads import modal_load
    from harness.mechanics.statics import fixed_mask
    lc = modal_load(case) if load is None else next(l for l in case.loads if l.name == load)
    free = ~fixed_mask(network.points, case, lc).ravel()
    return frequencies_arrays(network.points, network.springs, network.k, network.masses, free, n_modes)
