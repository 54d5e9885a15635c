"""G after changing one spring constant, without a new factorisation.

Changing k_e by delta changes each load's free-block stiffness by the rank-1 term
delta b b^T (b = b_e restricted to the free dofs). With z = K^-1 b, Sherman-Morrison gives

    u' = u - s z,   s = delta (b.u) / (1 + delta (b.z)),

and with d = u_ref - u, r = W d the new squared error needs no u':

    |d'|_W^2 = |d|_W^2 + 2 s (z.r) + s^2 (z.Wz).

Accepted changes since the last renewal of the base K0 are held in Woodbury form,
K = K0 + Bm D Bm^T: with the basis Z = K0^-1 Bm (one column y = K0^-1 b per accepted
spring) and M = D^-1 + Bm^T Z,

    z = y - Z c,  c = M^-1 (Z^T b),      u = u0 - Z C  (C: m x loads, updated per accept).

Nothing of length n (the free dofs) is touched per proposal: z.r and z.Wz expand into
small Gram matrices, H = Z^T W Z and P = Z^T r0 (kept, one row per accept), and per
batch of upcoming proposals Y = K0^-1 B_batch, A = Z^T W Y, Y^T W Y, Y^T r0 -- one
multi-right-hand-side solve and a few matrix products (BLAS-3) per batch. A proposal
then costs O(m^2) (m = accepts held) for all load sets at once; an accept appends one
column to Z and borders M^-1, H, C, P (O(m^2), no inverse).

y comes from a maintained dense inverse of K0 (small systems: a row gather) or from a
kept sparse factorisation (a batched solve). After ``refactor_every`` accepts the base is
renewed (dense: Kinv -= Z M^-1 Z^T, one matrix product; sparse: a new factorisation),
u0 and G are recomputed from it, so rounding cannot drift; the rest of the current batch
is carried over by Woodbury. By default the interval balances the renewal's cost
against the growing per-proposal Gram work (:func:`auto_interval`).
"""

from __future__ import annotations

import numpy as np

from harness.optimize.problem import FitProblem


class _Set:
    """One stacked entry: a load set's loads that share K and the dof weights W."""

    def __init__(self, ls, cols, const):
        self.ls = ls
        self.n = ls.B.shape[0]
        self.F = ls.F[:, cols]
        self.Uref = ls.Uref[:, cols]
        self.w = ls.W[:, cols[0]].copy()
        self.const = const
        self.Bt = ls.B.T.tocsr()   # rows b_e^T: a batch's right-hand sides


def _split(ls):
    """Loads of a load set grouped by identical weights (the Grams need one W)."""
    groups: list[list[int]] = []
    for j in range(ls.W.shape[1]):
        for g in groups:
            if np.array_equal(ls.W[:, g[0]], ls.W[:, j]):
                g.append(j)
                break
        else:
            groups.append([j])
    return [_Set(ls, g, ls.const if i == 0 else 0.0) for i, g in enumerate(groups)]


SOLVE_LEAF = 32   # dofs per leaf front of the engine's factorisation (see sparse_factor)


def sparse_factor(ls, k):
    """The sparse engine's factorisation of a load set's K(k): multifrontal Cholesky on
    a nested-dissection tree with small leaves (32 dofs), whose batched solves cost about
    half those of the general-purpose leaves of 256 (less fill: 0.28 M vs 0.69 M entries of
    L on the 2,500-node grid) at the price of a slower factorisation, paid once per renewal.
    Small blocks (no coordinates or <= 2,000 dofs) use the load set's own solver."""
    from harness.optimize.multifrontal import MultifrontalCholesky, Symbolic, warm_up
    if ls.coords is None or ls.B.shape[0] <= 2000:
        return ls.factor(k)
    warm_up()   # load the compiled substitution now, not inside the timed SA loop
    K = ls.stiffness(k)
    sym = ls.__dict__.get("_sa_symbolic")
    if sym is None:
        sym = Symbolic(K, ls.coords, leaf=SOLVE_LEAF)
        ls._sa_symbolic = sym  # pattern-only, reused by every engine on this problem
    return MultifrontalCholesky(K, sym, ls.name)


AUTO_CAP = 256  # most accepted steps held in Woodbury form (memory: nfree x 256 per load set)
AUTO_MIN = 32
DENSE_INTERVAL = 64


def auto_interval(sets, mode: str) -> int:
    """Accepts between renewals. Dense: 64 (the renewal is one BLAS-3 product of 2 n^2 m
    flops, i.e. 2 n^2 per accept whatever m, so m only bounds the O(m^2) work). Sparse:
    a renewal costs about F (the factorisations' flops, run at ~1/3 the rate of the
    Gram products) and each held column costs 2 n flops per proposal in A = Z^T W Y; the
    amortised F/m + n m is least at m = sqrt(3 F / n); clipped to [AUTO_MIN, AUTO_CAP].
    Deterministic (flop counts, no timing), so a seeded run is reproducible bit for bit."""
    if mode == "dense":
        return DENSE_INTERVAL
    F = 0.0
    n = 0
    for st in sets:
        n += st.n
        sym = getattr(getattr(st, "fac", None), "sym", None)
        if sym is None:
            return 64
        F += sum(nd["nv"] ** 3 / 3 + nd["nv"] ** 2 * len(nd["U"]) + nd["nv"] * len(nd["U"]) ** 2 for nd in sym.nodes)
    return int(np.clip(np.sqrt(3.0 * F / n), AUTO_MIN, AUTO_CAP))


class IncrementalG:
    """G of the current constants and of one-spring proposals (see module docstring).

    ``mode``: "dense" (maintained inverse), "sparse" (kept factorisation + Woodbury) or
    "auto" (dense when every free block has <= ``dense_max`` dofs). ``refactor_every``:
    accepted steps between renewals of the base, or "auto" (:func:`auto_interval`).
    ``batch``: proposals (this one and ``upcoming``) whose K0^-1 b_e are computed
    together. ``upcoming`` (set by the caller) holds the springs proposed next.

    All load sets are stacked on a leading axis, so a proposal is a fixed number of
    numpy calls whatever the number of loads. M^-1 is kept in product form
    T diag(1/sigma) T^T (T unit upper triangular, column j = [-c_j; 1], the accepted
    z_j = Z t_j): an accept writes one column, no rank-1 update of an m x m matrix."""

    def __init__(self, problem: FitProblem, k, mode: str = "auto", refactor_every="auto",
                 batch: int = 32, dense_max: int = 2500):
        self.problem = problem
        self.k = np.array(k, float)
        lsets = problem.load_sets()
        if mode == "auto":
            mode = "dense" if max(ls.B.shape[0] for ls in lsets) <= dense_max else "sparse"
        if mode not in ("dense", "sparse"):
            raise ValueError(f"unknown incremental mode {mode!r}")
        self.mode = mode
        self.batch = max(int(batch), 1)
        self.sets = [st for ls in lsets for st in _split(ls)]
        S = len(self.sets)
        self.S = S
        self.nmax = max(max(st.n for st in self.sets), 1)
        self.L = max(st.F.shape[1] for st in self.sets)
        self.const = sum(st.const for st in self.sets)
        self._gather_maps()
        self._factor_all()
        cap = auto_interval(self.sets, mode) if refactor_every == "auto" else int(refactor_every)
        self.refactor_every = self.cap = max(cap, 1)
        nm, L, cap, q, P = self.nmax, self.L, self.cap, self.batch, self.gi.shape[2]
        self.Zt = np.zeros((S, cap, nm))         # rows: K0^-1 b of the accepted springs
        self.X = np.zeros((S, 2, cap, cap))      # [T; H T] with H = Z^T W Z
        self.sig = np.ones((S, cap))             # sigma_j = 1/delta_j + b_j^T z_j
        self.C = np.zeros((S, cap, L))           # u = u0 - Z C
        self.P = np.zeros((S, cap, L))           # Z^T r0
        self.acc_i = np.zeros((S, cap, P), np.int64)  # b of the accepted springs: rows ...
        self.acc_v = np.zeros((S, cap, P))            # ... and values
        self.AA = np.zeros((S, cap, q))          # Z^T W Y for the current batch
        self.Yt = np.zeros((S, q, nm))           # rows: K0^-1 b for the batch's springs
        self.YY = np.zeros((S, q, q))            # Y^T W Y
        self.YR = np.zeros((S, q, L))            # Y^T r0
        self.bY = np.zeros((S, q))               # b_j^T y_j
        self.sidx = np.arange(S)[:, None, None]
        self.m = 0
        self.col: dict[int, int] = {}            # spring -> batch column
        self.upcoming: np.ndarray = np.empty(0, int)
        self.n_rebase = 0
        self._pending = None
        self._base_state()

    # --- set-up ----------------------------------------------------------------------
    def _gather_maps(self):
        """Per spring and set: rows (local, and flat into a stacked (S * nmax) array) and
        values of b_e, padded to the most entries of any column with value 0."""
        e = self.problem.n_springs
        P = max(1, max(int(np.max(np.diff(st.Bt.indptr), initial=0)) for st in self.sets))
        gi = np.zeros((e, self.S, P), np.int64)
        gv = np.zeros((e, self.S, P))
        for s, st in enumerate(self.sets):
            cnt = np.diff(st.Bt.indptr)
            for p in range(P):
                ok = np.nonzero(cnt > p)[0]
                gi[ok, s, p] = st.Bt.indices[st.Bt.indptr[ok] + p]
                gv[ok, s, p] = st.Bt.data[st.Bt.indptr[ok] + p]
        self.gi, self.gv = gi, gv
        self.gf = gi + (np.arange(self.S, dtype=np.int64) * self.nmax)[None, :, None]

    def _factor_all(self):
        fac = {}
        for st in self.sets:
            key = id(st.ls)
            if key not in fac:
                if self.mode == "dense":
                    fac[key] = np.linalg.inv(st.ls.stiffness(self.k).toarray()) if st.n else np.zeros((0, 0))
                else:
                    fac[key] = sparse_factor(st.ls, self.k) if st.n else None
            if self.mode == "dense":
                st.Kinv = fac[key]
            else:
                st.fac = fac[key]

    def _solve(self, st, rhs):
        if self.mode == "dense":
            return st.Kinv @ rhs
        return st.fac.solve(rhs).reshape(rhs.shape)

    def _base_state(self):
        """u0, r0 and the exact G^2 of the base."""
        S, nm, L = self.S, self.nmax, self.L
        self.U0 = np.zeros((S, nm, L))
        self.R0 = np.zeros((S, nm, L))
        self.G2s = np.zeros(S)
        for s, st in enumerate(self.sets):
            if st.n == 0:
                continue
            Ls = st.F.shape[1]
            U = self._solve(st, st.F)
            R = st.w[:, None] * (st.Uref - U)
            self.U0[s, :st.n, :Ls] = U
            self.R0[s, :st.n, :Ls] = R
            self.G2s[s] = float(np.sum((st.Uref - U) * R))
        self.U0f = self.U0.reshape(S * nm, L)

    # --- batches -----------------------------------------------------------------------
    def _new_batch(self, e):
        up = [int(x) for x in self.upcoming[: self.batch - 1]]
        springs = list(dict.fromkeys([e, *up]))[: self.batch]
        q = len(springs)
        self.Yt[:] = 0.0
        for s, st in enumerate(self.sets):
            if st.n == 0:
                continue
            rows = st.Bt[springs]
            if self.mode == "dense":   # rows of the symmetric inverse: 4 n flops per spring
                self.Yt[s, :q, :st.n] = rows @ st.Kinv
            else:
                self.Yt[s, :q, :st.n] = self._solve(st, np.asfortranarray(rows.T.toarray())).T
        self.col = {sp: j for j, sp in enumerate(springs)}
        self._batch_grams(springs, self.m)

    def _batch_grams(self, springs, m0):
        """A = Z^T W Y (first m0 rows), Y^T W Y, Y^T r0, b_j^T y_j for the batch."""
        q = len(springs)
        sp_arr = np.asarray(springs)
        gi, gv = self.gi[sp_arr], self.gv[sp_arr]            # (q, S, P)
        jj = np.arange(q)[:, None, None]
        self.bY[:, :q] = np.einsum("jsp,jsp->sj", gv, self.Yt[np.arange(self.S)[None, :, None], jj, gi])
        for s, st in enumerate(self.sets):
            n = st.n
            Y = self.Yt[s, :q, :n]
            WY = Y * st.w
            self.YY[s, :q, :q] = WY @ Y.T
            self.YR[s, :q] = Y @ self.R0[s, :n]
            if m0:
                self.AA[s, :m0, :q] = self.Zt[s, :m0, :n] @ WY.T

    # --- proposals ---------------------------------------------------------------------
    @property
    def G2(self) -> float:
        return float(np.sum(self.G2s)) + self.const

    def G(self) -> float:
        return float(np.sqrt(max(self.G2, 0.0)))

    def propose(self, e: int, k_new: float) -> float:
        delta = k_new - self.k[e]
        if delta == 0.0:  # clipped at a bound: a no-op, and 1/delta would poison the Woodbury core
            self._pending = (e, k_new, None)
            return self.G()
        j = self.col.get(e)
        if j is None:
            self._new_batch(e)
            j = self.col[e]
        m = self.m
        gv = self.gv[e]                                            # (S, P)
        bu = np.einsum("sp,spl->sl", gv, self.U0f[self.gf[e]])     # b^T u0
        if m:
            y_at = self.Yt[self.sidx, j, self.acc_i[:, :m]]        # (S, m, P)
            g = np.einsum("smp,smp->sm", self.acc_v[:, :m], y_at)   # Z^T b = Bm^T y
            ct = np.matmul(g[:, None, :], self.X[:, 0, :m, :m])[:, 0] / self.sig[:, :m]
            cH = np.matmul(self.X[:, :, :m, :m], ct[:, None, :, None])[..., 0]
            c, Hc = cH[:, 0], cH[:, 1]                              # M^-1 Z^T b, H c
            a = self.AA[:, :m, j]                                   # Z^T W y
            Cm = self.C[:, :m]
            bz = self.bY[:, j] - np.einsum("sm,sm->s", g, c)
            bu -= np.einsum("sm,sml->sl", g, Cm)
            zWz = self.YY[:, j, j] + np.einsum("sm,sm->s", c, Hc - 2.0 * a)
            zR = self.YR[:, j] - np.einsum("sm,sml->sl", c, self.P[:, :m]) + np.einsum("sm,sml->sl", a - Hc, Cm)
        else:
            c = a = Hc = None
            bz = self.bY[:, j]
            zWz = self.YY[:, j, j]
            zR = self.YR[:, j]
        s = (delta * bu) / (1.0 + delta * bz)[:, None]
        d2s = (s * (2.0 * zR + s * zWz[:, None])).sum(1)
        self._pending = (e, k_new, (delta, j, c, a, Hc, bz, s, d2s))
        return float(np.sqrt(max(self.G2 + float(d2s.sum()), 0.0)))

    def accept(self):
        e, k_new, pend = self._pending
        self._pending = None
        self.k[e] = k_new
        if pend is None:
            return
        delta, j, c, a, Hc, bz, s, d2s = pend
        m = self.m
        X = self.X
        if m:
            X[:, 0, :m, m] = -c
            X[:, 1, :m, m] = a - Hc                                 # H t, t = [-c; 1]
            X[:, 1, m, :m] = np.matmul(a[:, None, :], X[:, 0, :m, :m])[:, 0]   # a^T T
            X[:, 1, m, m] = self.YY[:, j, j] - np.einsum("sm,sm->s", a, c)
            self.C[:, :m] -= c[:, :, None] * s[:, None, :]
        else:
            X[:, 1, 0, 0] = self.YY[:, j, j]
        X[:, 0, m, m] = 1.0
        self.sig[:, m] = 1.0 / delta + bz
        self.C[:, m] = s
        self.P[:, m] = self.YR[:, j]
        self.AA[:, m, :] = self.YY[:, j, :]
        self.Zt[:, m] = self.Yt[:, j]
        self.acc_i[:, m] = self.gi[e]
        self.acc_v[:, m] = self.gv[e]
        self.G2s += d2s
        self.m = m + 1
        if self.m >= self.cap:
            self.rebase()

    def reject(self):
        self._pending = None

    # --- renewal -----------------------------------------------------------------------
    def _minv_apply(self, G):
        """M^-1 G for stacked G (S, m, r): T diag(1/sigma) T^T G."""
        m = self.m
        T = self.X[:, 0, :m, :m]
        return np.matmul(T, np.matmul(T.transpose(0, 2, 1), G) / self.sig[:, :m, None])

    def rebase(self):
        """Fold the accepted changes into a new base (dense: one product; sparse: a new
        factorisation); recompute u0 and G exactly; carry the batch over by Woodbury."""
        m = self.m
        self.n_rebase += 1
        springs = sorted(self.col, key=self.col.get)
        q = len(springs) if self.mode == "sparse" else 0   # dense: a new batch is a cheap gather
        if m and q:   # carried batch: y_new = y - Z M^-1 Z^T b
            y_at = self.Yt[self.sidx, :q, self.acc_i[:, :m]]        # (S, m, P, q)
            G = np.einsum("smp,smpj->smj", self.acc_v[:, :m], y_at)  # Bm^T Y = Z^T B
            self.Yt[:, :q] -= np.matmul(self._minv_apply(G).transpose(0, 2, 1), self.Zt[:, :m])
        if self.mode == "dense" and m:
            done = set()
            for s, st in enumerate(self.sets):
                if id(st.Kinv) in done or st.n == 0:
                    continue
                done.add(id(st.Kinv))
                Zz = self.X[s, 0, :m, :m].T @ self.Zt[s, :m, :st.n]     # rows: accepted z_j
                st.Kinv -= Zz.T @ (Zz / self.sig[s, :m, None])
        elif m:
            self._factor_all()
        self.m = 0
        self.X[:] = 0.0
        self.sig[:] = 1.0
        self._base_state()
        if q:
            self._batch_grams(springs, 0)
        else:
            self.col = {}


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
