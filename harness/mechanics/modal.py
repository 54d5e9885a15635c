"""Natural frequencies of a spring network: (K - lambda M) u = 0 with M = diag(masses)
(Deussen 1995 eq. 13), constrained like a load case (default: the case's first one), in
Hz (sqrt(lambda) / 2 pi) like ``ReferenceSolution.frequencies``."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp
from scipy.sparse.linalg import eigs, eigsh

from harness.case.loads import modal_load
from harness.errors import ModelError
from harness.mechanics.statics import fixed_mask
from harness.models.springs import incidence, stiffness_matrix


def frequencies_arrays(
    points, springs, k, masses, free: np.ndarray, n_modes: int = 6
) -> np.ndarray:
    """First ``n_modes`` frequencies (Hz) on the free dofs (plain arrays)."""
    K = stiffness_matrix(incidence(points, springs), k)
    return matrix_frequencies(K, _positive(masses), free, n_modes)


def _positive(masses) -> np.ndarray:
    """The node masses, refused (one line) if any is <= 0: M would not be positive definite."""
    masses = np.asarray(masses, float)
    if np.any(masses <= 0):
        raise ModelError(
            f"{int(np.sum(masses <= 0))} nodes have masses <= 0, so M is not positive definite",
            field="model.masses",
            fix="use masses = 'moments-nonneg', 'voronoi' or 'uniform'",
        )
    return masses


def matrix_frequencies(K, masses, free: np.ndarray, n_modes: int = 6) -> np.ndarray:
    """First ``n_modes`` frequencies (Hz) of a stiffness matrix K (ndof, ndof) with the
    node masses (n,) on the free dofs (also the linearised Bourguignon-Cani models):
    Re sqrt(lambda) / 2 pi of :func:`matrix_eigenvalues` (0 for a mode with lambda <= 0)."""
    lam = matrix_eigenvalues(K, masses, free, n_modes)
    return np.sqrt(lam.astype(complex)).real / (2 * np.pi)


def matrix_eigenvalues(K, masses, free: np.ndarray, n_modes: int = 6) -> np.ndarray:
    """The ``n_modes`` eigenvalues lambda of M^-1 K (free dofs) of smallest real part,
    in that order: real for a symmetric K; complex in general, because the Bourguignon-Cani
    element model is not conservative (its angular couples and volume forces are no
    energy's gradient, so its K is not symmetric and a symmetric solver, which reads one
    triangle, gives wrong and even negative values: the hexa MT "zero mode")."""
    masses = np.asarray(masses, float)
    dim = K.shape[0] // len(masses)
    fd = np.flatnonzero(np.asarray(free, bool))
    Kf = sp.csr_matrix(K)[fd][:, fd]
    s = 1 / np.sqrt(np.repeat(masses, dim)[fd])  # M^-1/2 K M^-1/2: same eigenvalues
    A = sp.diags(s) @ Kf @ sp.diags(s)
    n_modes = min(n_modes, len(fd))
    scale = max(abs(A).max(), 1e-300)
    symmetric = abs(A - A.T).max() <= 1e-12 * scale
    v0 = np.random.default_rng(0).standard_normal(A.shape[0])  # seeded: same bits every run
    if len(fd) <= 1500:
        if symmetric:
            lam = sl.eigh(A.toarray(), eigvals_only=True, subset_by_index=[0, n_modes - 1])
        else:
            lam = sl.eigvals(A.toarray())
    elif symmetric:
        lam = eigsh(A.tocsc(), k=n_modes, sigma=0.0, which="LM", return_eigenvectors=False, v0=v0)
    else:
        lam = eigs(
            A.tocsc(),
            k=min(n_modes + 2, len(fd) - 2),
            sigma=0.0,
            which="LM",
            return_eigenvectors=False,
            v0=v0,
        )
    lam = np.asarray(lam)
    lam = lam[np.lexsort((lam.imag, lam.real))][:n_modes]
    return lam.real if symmetric else lam


def frequencies(network, case, n_modes: int = 6, load: str | None = None) -> np.ndarray:
    """First ``n_modes`` natural frequencies (Hz) with the constraints of load ``load``
    (default: harness.case.loads.modal_load)."""
    lc = modal_load(case) if load is None else next(l for l in case.loads if l.name == load)
    free = ~fixed_mask(network.points, case, lc).ravel()
    if getattr(network, "volume", None) is not None:  # springs + volume: harness/models/volume.py
        return matrix_frequencies(
            network.stiffness_matrix(), _positive(network.masses), free, n_modes
        )
    return frequencies_arrays(
        network.points, network.springs, network.k, network.masses, free, n_modes
    )
