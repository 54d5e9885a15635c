"""Linear solves of the constrained stiffness: sparse direct (SuperLU), pyamg smoothed
aggregation with the rigid-body modes as near-null space, or Jacobi-preconditioned CG.

``auto`` picks direct in 2-D and for small 3-D systems; SuperLU's fill-in makes 3-D
direct solves impractical at ~1e5 dofs, where AMG-preconditioned CG is fast.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.errors import ModelError

DIRECT_MAX_3D = 8_000  # free dofs above which 'auto' uses pyamg in 3-D
RTOL = 1e-11


def choose(method: str, n: int, dim: int) -> str:
    if method != "auto":
        return method
    return "direct" if dim == 2 or n <= DIRECT_MAX_3D else "amg"


def solve(A: sp.csr_matrix, b: np.ndarray, method: str, near_null: np.ndarray | None = None) -> np.ndarray:
    """Solve A x = b (b (n,) or (n, m)) for symmetric positive definite A."""
    A = sp.csr_matrix(A)
    b2 = b.reshape(len(b), -1)
    if method == "direct":
        lu = spla.splu(A.tocsc(), permc_spec="COLAMD")
        x = lu.solve(np.ascontiguousarray(b2))
    elif method == "amg":
        import pyamg
        ml = pyamg.smoothed_aggregation_solver(A, B=near_null, symmetry="hermitian")
        x = np.column_stack([_amg_one(ml, A, col) for col in b2.T])
    elif method == "cg":
        d = A.diagonal()
        P = spla.LinearOperator(A.shape, matvec=lambda v: v / d)
        cols = []
        for col in b2.T:
            y, info = spla.cg(A, col, rtol=RTOL, atol=0.0, maxiter=20 * A.shape[0], M=P)
            if info != 0:
                raise ModelError(f"CG did not converge in {info} iterations", fix="use solver = 'amg' or 'direct'")
            cols.append(y)
        x = np.column_stack(cols)
    else:
        raise ValueError(method)
    if not np.all(np.isfinite(x)):
        raise ModelError("the stiffness matrix is singular", fix="check the constraints")
    return x.reshape(b.shape)


def _amg_one(ml, A, b):
    if not np.any(b):
        return np.zeros_like(b)
    res = []
    x = ml.solve(b, tol=RTOL, accel="cg", maxiter=500, residuals=res)
    if np.linalg.norm(b - A @ x) > 1e3 * RTOL * np.linalg.norm(b):
        raise ModelError(f"pyamg did not converge (residual {res[-1]:.2e})", fix="use solver = 'direct'")
    return x
