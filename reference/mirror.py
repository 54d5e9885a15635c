"""The cut planes of a mirror-symmetric solve: which mid-planes, with which parity
(reference/graded/symmetry.py decides them from the load), and the dofs held on them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Mirror:
    """Mid-planes the solve is cut at: ``axes`` and per axis the parity (+1, -1)."""

    axes: tuple[int, ...] = ()
    parities: tuple[int, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.axes)


def plane_dofs(doflocs: np.ndarray, centre, mirror: Mirror, tol: float) -> np.ndarray:
    """Interleaved vector dofs fixed on the cut planes: u_m on a symmetric cut, the
    other components on an antisymmetric one."""
    dim = doflocs.shape[0]
    out = []
    for m, p in zip(mirror.axes, mirror.parities):
        nodes = np.flatnonzero(np.abs(doflocs[m] - centre[m]) <= tol)
        comps = [m] if p > 0 else [c for c in range(dim) if c != m]
        out.append((dim * nodes[:, None] + np.asarray(comps)[None, :]).ravel())
    return np.unique(np.concatenate(out)) if out else np.zeros(0, np.int64)
