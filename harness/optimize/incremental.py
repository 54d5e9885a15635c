"""G after changing one spring constant, without a new factorisation.

Changing k_e by delta changes each load's free-block stiffness by the rank-1 term
delta b b^T (b = b_e restricted to the free dofs). With z = K^-1 b, Sherman-Morrison gives

    u' = u - s z,   s = delta (b.u) / (1 + delta (b.z)),

and with d = u_ref - u, r = W d the new squared error needs no u':

    |d'|_W^2 = |d|_W^2 + 2 s (z.r) + s^2 (z.Wz).

Accepted changes since the last renewal of the base K0 are held in Woodbury form,
K = K0 + Bm D Bm^T, in the basis of the accepted Sherman-Morrison vectors z_j: with
Z = K0^-1 Bm (one column y = K0^-1 b per accepted spring), V = Z T (T unit upper
triangular, column j = [-c_j; 1]) and sigma_j = 1/delta_j + b_j.z_j,

    K^-1 = K0^-1 - V diag(1/sigma) V^T,  z = y - V ct, ct = (V^T b) / sigma,  u = u0 - V Cv.

Nothing of length n (the free dofs) is touched per proposal: z.r and z.Wz expand into
small Gram matrices kept with one new row per accept (Hz = V^T W V, V^T r0, Cv), and per
batch of upcoming proposals (known in advance: the RNG draws them in chunks) into
Y = K0^-1 B_batch, V^T W Y, Y^T W Y, Y^T r0 -- one multi-right-hand-side solve and a
few BLAS-3 products per batch. A proposal then costs O(m^2) for all load sets at once
(m = accepts held; V^T b = T^T (Bm^T y) needs y only at the accepted springs' dofs), an
accept appends one row/column; both are compiled loops (numba) over the stacked sets.

y comes from a maintained dense inverse of K0 (small systems: a row gather) or from a
kept sparse factorisation (multifrontal Cholesky, batched compiled substitution). After
``refactor_every`` accepts the base is renewed (dense: Kinv -= V diag(1/sigma) V^T, one
product; sparse: a new factorisation), u0 and G are recomputed from it by a fresh solve,
so rounding cannot drift; the rest of the current batch is carried over by Woodbury.
By default the interval balances the renewal's cost against the per-proposal work that
grows with m (:func:`auto_interval`).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import dsyrk as syrk

from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic, _subst_kernel, warm_up
from harness.optimize.incremental_kernels import _accept, _kernels, _propose  # noqa: F401  (tests call the plain ones)
from harness.optimize.permatrix import per_matrix
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
        self.Bt = ls.B.T.tocsr()  # rows b_e^T: a batch's right-hand sides


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


SPARSE_MIN = 400  # below: the load set's dense Cholesky
SOLVE_LEAF = 64  # dofs per leaf front of the engine's factorisation (see sparse_factor)


def sparse_factor(ls, k):
    """The sparse engine's factorisation of a load set's K(k): multifrontal Cholesky on
    a nested-dissection tree with leaves of 64 dofs, whose batched solves cost ~2/3 of
    those with the general-purpose leaves of 256 (less fill: 0.35 M vs 0.69 M entries of
    L on the 2,500-node grid) for a slightly slower factorisation, paid once per renewal.
    Small blocks (no coordinates or <= SPARSE_MIN dofs) use the load set's own solver."""
    if ls.coords is None or ls.B.shape[0] <= SPARSE_MIN:
        return ls.factor(k)
    K = ls.stiffness(k)
    # every engine's
    sym = per_matrix(ls.B, "symbolic-sa", lambda: Symbolic(K, ls.coords, leaf=SOLVE_LEAF))
    fac = MultifrontalCholesky(K, sym, ls.name)
    if warm_up():  # compiled now, not in the timed loop; inverted diagonal blocks: every
        fac._flat(drop=True)  # solve with this factor takes the compiled path
    return fac


AUTO_MIN, AUTO_MAX = 64, 1024  # bounds of the automatic renewal interval (accepts)
AUTO_MEMORY = 400e6  # bytes for the held basis Z (S x interval x nfree doubles)
DENSE_INTERVAL = 64
NODE_FLOPS = 2e6  # a front's fixed cost in the factorisation, in flops (Python)


def auto_interval(sets, mode: str) -> int:
    """Accepts between renewals. Dense: 64 (a renewal is one product of 2 n^2 m flops, so
    2 n^2 per accept whatever the interval; m only bounds the O(m^2) work). Sparse: a
    renewal costs R = the factorisations' flops plus a fixed cost per front; each held
    column costs every proposal ~3 n flops (the Gram V^T W Y and the O(m) kernel work), n
    = all free dofs. The amortised R a / m + 1.5 n m (a ~ 0.9 accepts per proposal) is
    least at m = sqrt(R / (1.7 n)); clipped to [AUTO_MIN, AUTO_MAX] and to the memory
    budget. Measured on the bench grids the optimum is flat within a factor 1.5 of this.
    Deterministic (flop counts, no timing), so a seeded run is reproducible bit for bit."""
    if mode == "dense":
        return DENSE_INTERVAL
    R = 0.0
    n = 0
    seen = set()
    for st in sets:
        n += st.n
        sym = getattr(getattr(st, "fac", None), "sym", None)
        if sym is None:
            return DENSE_INTERVAL
        if id(st.fac) in seen:
            continue
        seen.add(id(st.fac))
        R += sum(
            nd["nv"] ** 3 / 3
            + nd["nv"] ** 2 * len(nd["U"])
            + nd["nv"] * len(nd["U"]) ** 2
            + NODE_FLOPS
            for nd in sym.nodes
        )
    nmax = max(st.n for st in sets)
    mem = AUTO_MEMORY / (8.0 * len(sets) * max(nmax, 1))
    return int(max(AUTO_MIN, min(np.sqrt(R / (1.7 * n)), AUTO_MAX, mem)))


class IncrementalG:
    """G of the current constants and of one-spring proposals (see module docstring).

    ``mode``: "dense" (maintained inverse), "sparse" (kept factorisation + Woodbury) or
    "auto" (dense when every free block has <= ``dense_max`` dofs). ``refactor_every``:
    accepted steps between renewals of the base, or "auto" (:func:`auto_interval`).
    ``batch``: proposals (this one and ``upcoming``) whose K0^-1 b_e are computed
    together. ``upcoming`` (set by the caller) holds the springs proposed next.

    All load sets are stacked on a leading axis and a proposal or an accept is one
    compiled call whatever the number of loads. The accepted changes are kept in the
    basis V = Z T of the accepted z_j (T unit upper triangular, column j = [-c_j; 1]),
    in which M^-1 = T diag(1/sigma) T^T and u = u0 - V Cv with Cv's columns the s_j:
    an accept writes one row/column and touches nothing else of size m^2."""

    def __init__(
        self,
        problem: FitProblem,
        k,
        mode: str = "auto",
        refactor_every="auto",
        batch: int = 64,
        dense_max: int = 1200,
    ):
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
        self._factor_all()
        self._elimination_order()
        self._gather_maps()
        cap = auto_interval(self.sets, mode) if refactor_every == "auto" else int(refactor_every)
        self.refactor_every = self.cap = max(cap, 1)
        nm, L, cap, q, P = self.nmax, self.L, self.cap, self.batch, self.gi.shape[2]

        def zeros(*shape, dtype=float):  # written now: no page faults inside the SA loop
            a = np.empty(shape, dtype)
            a.fill(0)
            return a

        self.Zt = zeros(S, cap, nm)  # rows: y = K0^-1 b of the accepted springs
        self.T = zeros(S, cap, cap)  # V = Z T
        self.Hz = zeros(S, cap, cap)  # V^T W V
        self.sig = zeros(S, cap)  # sigma_j = 1/delta_j + b_j^T z_j
        self.Cv = zeros(S, L, cap)  # u = u0 - V Cv^T
        self.PV = zeros(S, L, cap)  # V^T r0
        self.acc_i = zeros(S, cap, P, dtype=np.int64)  # b of the accepted springs: rows ...
        self.acc_v = zeros(S, cap, P)  # ... and values
        self.AV = zeros(S, cap, q)  # V^T W Y for the current batch
        self.Yt = zeros(S, q, nm)  # rows: K0^-1 b for the batch's springs
        self.YY = zeros(S, q, q)  # Y^T W Y
        self.YR = zeros(S, q, L)  # Y^T r0
        self.bY = zeros(S, q)  # b_j^T y_j
        self.scratch = (
            zeros(S, cap),
            zeros(S, cap),
            zeros(S),
            zeros(S, L),
            zeros(S),
            zeros(S, L),
            zeros(S),
        )
        self._kp, self._ka = _kernels()
        self.m = 0
        self.col: dict[int, int] = {}  # spring -> batch column
        self._last_j = -1  # batch column of the latest proposal
        self.upcoming: np.ndarray = np.empty(0, int)
        self.n_rebase = 0
        self._pending = None
        self._base_state()
        self._warm_up()

    # --- set-up
    def _warm_up(self):
        """Compile or load the kernels now (not inside a timed SA loop): a proposal and an
        accept at m = 0 on the empty batch; the next real accept overwrites what they wrote."""
        self._proposal(0, 0, 1.0)
        self._ka(
            0,
            0,
            1.0,
            self.gi[0],
            self.gv[0],
            self.T,
            self.Hz,
            self.sig,
            self.Cv,
            self.PV,
            self.AV,
            self.YY,
            self.Yt,
            self.Zt,
            self.acc_i,
            self.acc_v,
            *self.scratch[:6],
        )
        self.T[:, 0, 0] = 0.0

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
                    fac[key] = (
                        np.linalg.inv(st.ls.stiffness(self.k).toarray())
                        if st.n
                        else np.zeros((0, 0))
                    )
                else:
                    fac[key] = sparse_factor(st.ls, self.k) if st.n else None
            if self.mode == "dense":
                st.Kinv = fac[key]
            else:
                st.fac = fac[key]

    def _elimination_order(self):
        """Sparse mode: hold each set's dofs in its factor's elimination order (fixed: the
        symbolic factorisation is kept across renewals), so no solve permutes rows. G and
        all Grams are sums over dofs, hence independent of the order."""
        for st in self.sets:
            fac = getattr(st, "fac", None)
            st.ordered = isinstance(fac, MultifrontalCholesky) and _subst_kernel() is not None
            if st.ordered:
                order = fac.sym.order
                st.F, st.Uref, st.w = st.F[order], st.Uref[order], st.w[order]
                st.Bt = st.Bt[:, order].tocsr()
            st.sw = np.sqrt(st.w)

    def _solve(self, st, rhs):
        if self.mode == "dense":
            return st.Kinv @ rhs
        if st.ordered:
            return st.fac.solve_ordered(np.array(rhs, float, order="C"))
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
            self.U0[s, : st.n, :Ls] = U
            self.R0[s, : st.n, :Ls] = R
            self.G2s[s] = float(np.sum((st.Uref - U) * R))
        self.U0f = self.U0.reshape(S * nm, L)

    # --- batches -----------------------------------------------------------------------
    def _new_batch(self, e):
        up = [int(x) for x in self.upcoming[: self.batch - 1]]
        springs = list(dict.fromkeys([e, *up]))[: self.batch]
        q = len(springs)
        sp_arr = np.asarray(springs)
        cols = np.broadcast_to(np.arange(q)[:, None], (q, self.gi.shape[2]))
        for s, st in enumerate(self.sets):  # only rows < st.n of the first q of Yt are read
            if st.n == 0:
                continue
            if self.mode == "dense":  # rows of the symmetric inverse: 4 n flops per spring
                self.Yt[s, :q, : st.n] = st.Bt[springs] @ st.Kinv
            else:  # b_e as columns, scattered from the gather maps
                rhs = np.zeros((st.n, q))
                np.add.at(rhs, (self.gi[sp_arr, s], cols), self.gv[sp_arr, s])
                self.Yt[s, :q, : st.n] = self._solve(st, rhs).T
        self.col = {sp: j for j, sp in enumerate(springs)}
        self._last_j = -1
        self._batch_grams(springs, self.m)

    def _batch_grams(self, springs, m0):
        """V^T W Y (first m0 rows), Y^T W Y, Y^T r0, b_j^T y_j for the batch (BLAS-3)."""
        q = len(springs)
        sp_arr = np.asarray(springs)
        gi, gv = self.gi[sp_arr], self.gv[sp_arr]  # (q, S, P)
        jj = np.arange(q)[:, None, None]
        self.bY[:, :q] = np.einsum(
            "jsp,jsp->sj", gv, self.Yt[np.arange(self.S)[None, :, None], jj, gi]
        )
        for s, st in enumerate(self.sets):
            n = st.n
            Y = self.Yt[s, :q, :n]
            YY = syrk(1.0, (Y * st.sw).T, trans=1)  # upper triangle: half the flops of (Y W) Y^T
            self.YY[s, :q, :q] = np.triu(YY) + np.triu(YY, 1).T
            self.YR[s, :q] = Y @ self.R0[s, :n]
            if m0:
                self.AV[s, :m0, :q] = self.T[s, :m0, :m0].T @ (self.Zt[s, :m0, :n] @ (Y * st.w).T)

    # --- proposals ---------------------------------------------------------------------
    @property
    def G2(self) -> float:
        return float(np.sum(self.G2s)) + self.const

    def G(self) -> float:
        return float(np.sqrt(max(self.G2, 0.0)))

    def _proposal(self, e: int, j: int, delta: float) -> float:
        """The proposal kernel for spring e (batch column j, k += delta) on the current
        state: the change of G^2."""
        return self._kp(
            self.m,
            j,
            delta,
            self.gf[e],
            self.gv[e],
            self.U0f,
            self.Yt.reshape(-1),
            self.batch,
            self.nmax,
            self.acc_i,
            self.acc_v,
            self.T,
            self.Hz,
            self.sig,
            self.Cv,
            self.PV,
            self.AV,
            self.YY,
            self.YR,
            self.bY,
            *self.scratch,
        )

    def propose(self, e: int, k_new: float) -> float:
        delta = k_new - self.k[e]
        if delta == 0.0:  # clipped at a bound: a no-op, and 1/delta would poison the Woodbury core
            self._pending = (e, k_new, None)
            return self.G()
        j = self.col.get(e)
        if j is None:
            self._new_batch(e)
            j = self.col[e]
        d2 = self._proposal(e, j, delta)
        self._pending = (e, k_new, (delta, j))
        self._last_j = j
        return float(np.sqrt(max(self.G2 + d2, 0.0)))

    def accept(self):
        e, k_new, pend = self._pending
        self._pending = None
        self.k[e] = k_new
        if pend is None:
            return
        delta, j = pend
        m = self.m
        sc = self.scratch
        self._ka(
            m,
            j,
            delta,
            self.gi[e],
            self.gv[e],
            self.T,
            self.Hz,
            self.sig,
            self.Cv,
            self.PV,
            self.AV,
            self.YY,
            self.Yt,
            self.Zt,
            self.acc_i,
            self.acc_v,
            *sc[:6],
        )
        self.G2s += sc[6]
        self.m = m + 1
        if self.m >= self.cap:
            self.rebase()

    def reject(self):
        self._pending = None

    # --- renewal -----------------------------------------------------------------------
    def rebase(self):
        """Fold the accepted changes into a new base (dense: one product; sparse: a new
        factorisation); recompute u0 and G exactly; carry the batch over by Woodbury."""
        m = self.m
        self.n_rebase += 1
        # the batch's columns still to come (after the last proposal) are carried over
        springs = sorted((sp for sp, j in self.col.items() if j > self._last_j), key=self.col.get)
        if self.mode == "dense":
            springs = []  # a new batch is a cheap gather
        q = len(springs)
        T = self.T[:, :m, :m]
        if q:
            Y = self.Yt[:, [self.col[sp] for sp in springs]]
            self.Yt.fill(0.0)
            self.Yt[:, :q] = Y
        if m and q:  # carried batch: y_new = y - V diag(1/sigma) V^T b, V = Z T
            y_at = self.Yt[np.arange(self.S)[:, None, None], :q, self.acc_i[:, :m]]  # (S, m, P, q)
            G = np.einsum("smp,smpj->smj", self.acc_v[:, :m], y_at)  # Z^T B
            W2 = np.matmul(T, np.matmul(T.transpose(0, 2, 1), G) / self.sig[:, :m, None])
            self.Yt[:, :q] -= np.matmul(W2.transpose(0, 2, 1), self.Zt[:, :m])
        if self.mode == "dense" and m:
            done = set()
            for s, st in enumerate(self.sets):
                if id(st.Kinv) in done or st.n == 0:
                    continue
                done.add(id(st.Kinv))
                Vt = T[s].T @ self.Zt[s, :m, : st.n]  # rows: accepted z_j
                st.Kinv -= Vt.T @ (Vt / self.sig[s, :m, None])
        elif m:
            self._factor_all()
        self.m = 0
        self.T[:, :m, :m] = 0.0
        self._base_state()
        self.col = {sp: i for i, sp in enumerate(springs)}
        self._last_j = -1
        if q:
            self._batch_grams(springs, 0)
