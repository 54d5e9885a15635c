"""G after changing one spring constant, without a new factorisation.

Changing k_e by delta changes each load's free-block stiffness by the rank-1 term
delta b b^T (b = b_e restricted to the free dofs). With z = K^-1 b, Sherman-Morrison gives

    u' = u - s z,   s = delta (b.u) / (1 + delta (b.z)),

and with d = u_ref - u, r = W d the new squared error needs no u':

    |d'|_W^2 = |d|_W^2 + 2 s (z.r) + s^2 (z.Wz).

z costs O(nfree): a row gather from a dense inverse of K (small systems), or one
triangular solve with a kept sparse factorisation K0 (batched over the coming proposals,
many right-hand sides at once). Accepted changes since the last factorisation are folded
in by Woodbury: K = K0 + U D U^T, so z = y - Z0 M^-1 (Z0^T b) with y = K0^-1 b,
Z0 = K0^-1 U, M = D^-1 + U^T Z0. After ``refactor_every`` accepts the base is renewed
(dense: one matrix product Kinv -= Z0 M^-1 Z0^T; sparse: a new factorisation) and u, G
are recomputed from it, so rounding cannot drift. By default the sparse interval balances
the flops of a renewal against the growing Woodbury correction (auto_interval): 64
accepts (the issue's 32-64) unless a renewal is expensive, as on large 3-D networks where
it means six big factorisations.
"""

from __future__ import annotations

import numpy as np

from harness.optimize.problem import FitProblem


class _Set:
    """State of one free-dof set (loads that share K)."""

    def __init__(self, ls, k, dense: bool, cap: int):
        self.ls = ls
        self.B = ls.B.tocsc()
        self.dense = dense
        self.cap = cap
        n = self.B.shape[0]
        self.Z = np.empty((n, cap))
        self.M = np.empty((cap, cap))
        self.cols: list[tuple[np.ndarray, np.ndarray]] = []
        self.rebase(k)

    def column(self, e):
        a, b = self.B.indptr[e], self.B.indptr[e + 1]
        return self.B.indices[a:b], self.B.data[a:b]

    def rebase(self, k, Kinv_update=False):
        ls = self.ls
        m = len(self.cols)
        old_cache = getattr(self, "ycache", {})
        if self.dense:
            if Kinv_update and m:
                Y = self.Z[:, :m] @ self.Minv
                self.Kinv -= Y @ self.Z[:, :m].T
            else:
                self.Kinv = np.linalg.inv(ls.stiffness(k).toarray())
            self.U = self.Kinv @ ls.F
            old_cache = {}
        else:
            self.fac = ls.factor(k, kind="multifrontal")   # batched solves: multifrontal is faster
            self.U = self.fac.solve(ls.F)
        self.U = self.U.reshape(ls.F.shape)
        self.R = ls.W * (ls.Uref - self.U)
        self.G2 = float(np.sum((ls.Uref - self.U) * self.R)) + ls.const
        self.ycache: dict[int, np.ndarray] = {}
        if old_cache and m:  # carry prefetched K0^-1 b over to the new base by Woodbury
            springs = list(old_cache)
            Y = np.stack([old_cache[e] for e in springs], 1)
            ZtB = np.empty((m, len(springs)))
            for j, e in enumerate(springs):
                idx, val = self.column(e)
                ZtB[:, j] = val @ self.Z[idx, :m]
            Y -= self.Z[:, :m] @ (self.Minv @ ZtB)
            self.ycache = {e: Y[:, j] for j, e in enumerate(springs)}
        self.cols = []
        self.Minv = np.empty((0, 0))

    def prefetch(self, springs):
        """Sparse base: y = K0^-1 b_e for many springs in one multi-RHS solve."""
        wanted = list(dict.fromkeys(int(s) for s in springs))
        self.ycache = {e: self.ycache[e] for e in wanted if e in self.ycache}  # stale entries go
        springs = [e for e in wanted if e not in self.ycache]
        if not springs:
            return
        n = self.B.shape[0]
        rhs = self.B[:, springs].toarray() if n else np.zeros((0, len(springs)))
        nz = np.any(rhs != 0, axis=0)
        Y = np.zeros_like(rhs)
        if nz.any():
            Y[:, nz] = self.fac.solve(np.asfortranarray(rhs[:, nz])).reshape(n, -1)
        for j, e in enumerate(springs):
            self.ycache[e] = Y[:, j]

    def y(self, e, idx, val, upcoming):
        if self.dense:
            return val @ self.Kinv[idx, :]
        y = self.ycache.pop(e, None)   # used once: the cache stays at most one batch
        if y is None:
            self.prefetch([e, *upcoming])
            y = self.ycache.pop(e)
        return y

    def propose(self, e, delta, upcoming):
        idx, val = self.column(e)
        if len(idx) == 0:
            return 0.0, None
        y = self.y(e, idx, val, upcoming)
        m = len(self.cols)
        if m:
            c = self.Minv @ (val @ self.Z[idx, :m])
            z = y - self.Z[:, :m] @ c
        else:
            z = y
        bz = float(val @ z[idx])
        bu = val @ self.U[idx]
        s = delta * bu / (1.0 + delta * bz)
        d2 = float(np.sum(2.0 * s * (z @ self.R) + s * s * ((z * z) @ self.ls.W)))
        return d2, (z, s, y, idx, val, delta)

    def accept(self, pending, d2):
        z, s, y, idx, val, delta = pending
        self.U -= z[:, None] * s[None, :]
        self.R += (self.ls.W * z[:, None]) * s[None, :]
        self.G2 += d2
        m = len(self.cols)
        self.Z[:, m] = y
        zb = val @ self.Z[idx, :m + 1]
        self.M[m, :m + 1] = zb
        self.M[:m + 1, m] = zb
        self.M[m, m] += 1.0 / delta
        self.cols.append((idx, val))
        self.Minv = np.linalg.inv(self.M[:m + 1, :m + 1])
        return m + 1 >= self.cap


AUTO_CAP = 256  # most accepted steps held in Woodbury form (memory: nfree x 256 per load set)
AUTO_MIN = 64


def auto_interval(sets) -> int:
    """Accepts between renewals of a sparse base: with F the flops of the factorisations
    and 4 n flops per proposal per held column (n = all free dofs), the amortised cost
    F/m + 2 n m (BLAS-2 correction, ~10x slower per flop than the BLAS-3 factorisation)
    is least at m = sqrt(F / (20 n)); clipped to [AUTO_MIN, AUTO_CAP]. Deterministic,
    so a seeded run is reproducible bit for bit."""
    F = 0.0
    n = 0
    for st in sets:
        n += st.B.shape[0]
        sym = getattr(getattr(st, "fac", None), "sym", None)
        if sym is None:
            return 64
        F += sum(nd["nv"] ** 3 / 3 + nd["nv"] ** 2 * len(nd["U"]) + nd["nv"] * len(nd["U"]) ** 2 for nd in sym.nodes)
    return int(np.clip(np.sqrt(F / (20.0 * n)), AUTO_MIN, AUTO_CAP))


class IncrementalG:
    """G of the current constants and of one-spring proposals (see module docstring).

    ``mode``: "dense" (maintained inverse), "sparse" (kept factorisation + Woodbury) or
    "auto" (dense when every free block has <= ``dense_max`` dofs). ``refactor_every``:
    accepted steps between renewals of the base, or "auto" (dense: 64; sparse:
    :func:`auto_interval`)."""

    def __init__(self, problem: FitProblem, k, mode: str = "auto", refactor_every="auto",
                 batch: int = 32, dense_max: int = 2500):
        self.problem = problem
        self.k = np.array(k, float)
        sets = problem.load_sets()
        if mode == "auto":
            mode = "dense" if max(ls.B.shape[0] for ls in sets) <= dense_max else "sparse"
        self.mode = mode
        self.batch = batch
        if refactor_every == "auto":
            refactor_every = 64 if mode == "dense" else None
        self.sets = [_Set(ls, self.k, mode == "dense", int(refactor_every or AUTO_CAP)) for ls in sets]
        if refactor_every is None:  # balance renewal flops against Woodbury flops (deterministic)
            refactor_every = auto_interval(self.sets)
            for st in self.sets:
                st.cap = refactor_every
        self.refactor_every = int(refactor_every)
        self.upcoming: np.ndarray = np.empty(0, int)
        self.n_rebase = 0
        self._pending = None

    @property
    def G2(self) -> float:
        return sum(s.G2 for s in self.sets)

    def G(self) -> float:
        return float(np.sqrt(max(self.G2, 0.0)))

    def propose(self, e: int, k_new: float) -> float:
        delta = k_new - self.k[e]
        if delta == 0.0:  # clipped at a bound: a no-op, and 1/delta would poison the Woodbury core
            self._pending = (e, k_new, [(0.0, None)] * len(self.sets))
            return self.G()
        up = self.upcoming[: self.batch - 1]
        parts = [s.propose(e, delta, up) for s in self.sets]
        d2 = sum(p[0] for p in parts)
        self._pending = (e, k_new, parts)
        return float(np.sqrt(max(self.G2 + d2, 0.0)))

    def accept(self):
        e, k_new, parts = self._pending
        self.k[e] = k_new
        full = False
        for s, (d2, pend) in zip(self.sets, parts):
            if pend is not None:
                full |= s.accept(pend, d2)
        if full:
            self.rebase()
        self._pending = None

    def reject(self):
        self._pending = None

    def rebase(self):
        """Fold the accepted changes into the base (dense: one product; sparse: refactor)."""
        self.n_rebase += 1
        for s in self.sets:
            s.rebase(self.k, Kinv_update=True)


class RefactorG:
    """The paper's way: every proposal re-assembles and re-factorises K for each load
    set. Same interface as IncrementalG; the baseline of ``bench sa``."""

    mode = "refactor"

    def __init__(self, problem: FitProblem, k, **_):
        self.problem = problem
        self.k = np.array(k, float)
        self._G = problem.G(self.k)
        self._pending = None
        self.upcoming = np.empty(0, int)
        self.n_rebase = 0

    def G(self) -> float:
        return self._G

    def propose_k(self, k_new_vec) -> float:
        G = self.problem.G(k_new_vec)
        self._pending = (np.array(k_new_vec, float), G)
        return G

    def propose(self, e: int, k_new: float) -> float:
        k = self.k.copy()
        k[e] = k_new
        return self.propose_k(k)

    def accept(self):
        self.k, self._G = self._pending
        self._pending = None

    def reject(self):
        self._pending = None
