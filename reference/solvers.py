"""Linear solves of the constrained stiffness: sparse direct (SuperLU), pyamg smoothed
aggregation with the rigid-body modes as near-null space, or Jacobi-preconditioned CG.

``auto`` picks direct for small systems; SuperLU's fill-in makes 3-D direct solves
impractical at ~1e5 dofs, where AMG-preconditioned CG is fast.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.errors import ModelError

# free dofs above which 'auto' uses pyamg (crossovers measured by `springbench bench
# reference`: 3-D P2 direct 1.7 s vs amg 4.6 s at 11k dofs, 41 s vs 11 s at 36k; 2-D
# direct 7 s vs 13 s at 66k, 95 s vs 42 s at 264k)
DIRECT_MAX = {2: 150_000, 3: 20_000}
RTOL = 1e-11


def choose(method: str, n: int, dim: int) -> str:
    if method != "auto":
        return method
    return "direct" if n <= DIRECT_MAX[dim] else "amg"


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
