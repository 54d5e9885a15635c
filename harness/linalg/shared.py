"""One factorisation for several Dirichlet restrictions of one SPD matrix.

Load sets of one network that hold different dofs (the free-traction states' minimal
constraints, each clamped state's face) have stiffness matrices that are principal
submatrices of one matrix K on the union of their free dofs. Ordered with the dofs some
set holds (S) after all others (I, free in every set), one multifrontal factorisation
eliminates I once for all sets; its root front is the Schur complement of K on S, and a
set's own Schur complement on its free part of S is a principal submatrix of it (the
elimination of I never touches S's rows), so a set costs one dense Cholesky of at most
|S| dofs. The result is exact: a set's solution is the one of its own matrix, factorised
in that order. Right-hand sides of all sets go through the shared fronts together.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from harness.errors import ModelError
from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
from harness.linalg.sparse import single_thread_blas
from harness.linalg.stiffness import restriction, stiffness_map


class SharedSets:
    """The restrictions of K = B diag(k) B^T to the free dofs of several sets: ``Bs`` per
    set its incidence rows (one network's columns), ``dofs`` per set its free dofs' ids
    (ascending, as its rows), ``coords`` per set its rows' positions (the ordering);
    ``whole``: None, or two functions: () -> the pattern of the network's whole K, and
    k -> its values; K is their restriction to the union (its own map is not built)."""

    def __init__(self, Bs, dofs, coords, name: str = "", whole=None):
        dofs = [np.asarray(d, np.int64) for d in dofs]
        self.union = np.unique(np.concatenate(dofs))
        self.keeps = [np.searchsorted(self.union, d) for d in dofs]
        # each union dof's row from the first set that has it
        first = np.full(len(self.union), -1)
        for c in reversed(range(len(dofs))):
            first[self.keeps[c]] = c
        rows, X, at = [], [], []
        for c, (B, kp) in enumerate(zip(Bs, self.keeps)):
            mine = np.flatnonzero(first[kp] == c)
            rows.append(sp.csr_matrix(B)[mine])
            X.append(np.asarray(coords[c], float)[mine])
            at.append(kp[mine])
        at = np.concatenate(at)
        order = np.argsort(at)
        self.B = sp.vstack(rows).tocsr()[order].tocsc()
        self.coords = np.concatenate(X)[order]
        self.name = name
        self.whole, self.values = whole if whole is not None else (None, None)
        self._map = None
        count = np.zeros(len(self.union), np.int64)
        for kp in self.keeps:
            count[kp] += 1
        held = np.flatnonzero(count < len(dofs))
        if not len(held):
            raise ValueError("sets with the same free dofs are one set: nothing to share")
        self.sym = Symbolic(abs(self.B) @ abs(self.B).T, self.coords, last=held)
        pos = np.full(len(self.union), -1)
        pos[self.sym.nodes[-1]["V"]] = np.arange(len(held))
        # per set: its free dofs of the root front, in the front's (elimination) order
        self.root_keep = [np.sort(pos[kp][pos[kp] >= 0]) for kp in self.keeps]
        self.n_held = len(held)

    def estimate(self) -> float:
        """Gflop of one factorisation: the shared fronts and every set's root Cholesky."""
        nodes = self.sym.nodes[:-1]
        nv = np.array([nd["nv"] for nd in nodes], float)
        nu = np.array([len(nd["U"]) for nd in nodes], float)
        flop = np.sum(nv**3 / 3 + nv**2 * nu + nv * nu**2)
        flop += sum(len(r) ** 3 / 3 for r in self.root_keep)
        return float(flop / 1e9)

    def stiffness(self, k) -> sp.csc_matrix:
        """K on the union of the free dofs (the map k -> K, or its restriction of the
        network's, built at the first call)."""
        if self._map is None:
            if self.values is None:
                self._map = (*stiffness_map(self.B), None)
            else:
                pattern, gather = restriction(self.whole(), self.union)
                self._map = (pattern, None, gather)
        pattern, kmap, gather = self._map
        K = pattern.copy()
        k = np.asarray(k, float)
        K.data = kmap @ k if gather is None else self.values(k)[gather]
        return K

    def factor(self, k) -> "SharedFactor":
        return SharedFactor(self, self.stiffness(k))


class SharedFactor:
    """The shared fronts of K(k) factorised once, and each set's root Cholesky."""

    def __init__(self, sets: SharedSets, K: sp.spmatrix):
        self.sets = sets
        with single_thread_blas():
            self._factor(sets, K)

    def _factor(self, sets: SharedSets, K) -> None:
        self.mf = MultifrontalCholesky(K, sets.sym, sets.name, keep_root=True)
        R = self.mf.root
        self.roots = []
        for rk in sets.root_keep:
            if not len(rk):
                self.roots.append(None)
                continue
            L, info = sla.lapack.dpotrf(R[np.ix_(rk, rk)], lower=1, clean=1)
            d = np.diag(L) if info == 0 else np.zeros(1)
            if info != 0 or d.min() < 1e-7 * d.max():
                raise ModelError(
                    f"load '{sets.name}': stiffness matrix is singular or not positive definite",
                    field="springs",
                    fix="the network has a mechanism or floating node, or a spring constant <= 0",
                )
            self.roots.append(L)

    def solve(self, rhs: list) -> list:
        """K_c^-1 rhs[c] for every set c (rhs[c]: (its free dofs, q_c)), all through the
        shared fronts at once."""
        s = self.sets
        widths = [np.asarray(r).reshape(len(kp), -1).shape[1] for r, kp in zip(rhs, s.keeps)]
        cols = np.concatenate([[0], np.cumsum(widths)])
        b = np.zeros((len(s.union), cols[-1]))
        for c, (r, kp) in enumerate(zip(rhs, s.keeps)):
            b[kp, cols[c] : cols[c + 1]] = np.asarray(r, float).reshape(len(kp), -1)
        order = s.sym.order
        b = np.ascontiguousarray(b[order])
        root = s.sym.nodes[-1]["sl"]
        trtrs = sla.lapack.dtrtrs
        with single_thread_blas():
            self.mf.forward(b)
            z = b[root].copy()
            b[root] = 0.0
            for c, (rk, L) in enumerate(zip(s.root_keep, self.roots)):
                if L is None:
                    continue
                part = z[rk, cols[c] : cols[c + 1]]
                y = trtrs(L, part, lower=1)[0]
                b[root.start + rk, cols[c] : cols[c + 1]] = trtrs(L, y, lower=1, trans=1)[0]
            self.mf.backward(b)
        out = np.empty_like(b)
        out[order] = b
        return [
            out[kp, cols[c] : cols[c + 1]].reshape(np.shape(r))
            for c, (r, kp) in enumerate(zip(rhs, s.keeps))
        ]


def best_group(Bs, dofs, coords, alone, names, whole=None):
    """(positions, in the order of their :class:`SharedSets`, and it) of the sets (``Bs``,
    ``dofs``, ``coords`` as SharedSets'; ``alone``: each set's own factorisation's Gflop)
    that share a factorisation, or None: from the set with the most free dofs, each other
    set (largest first) joins when the group's flops with it are fewer than the group's
    without it plus its own. A set that holds a large part of the body (a clamped face as
    big as a side) stays apart: its held dofs would make the shared root large and dense.
    ``whole``: as SharedSets'."""
    order = sorted(range(len(Bs)), key=lambda i: -Bs[i].shape[0])
    group, cost, shared = [order[0]], alone[order[0]], None
    for i in order[1:]:
        trial = [*group, i]
        cand = SharedSets(
            [Bs[j] for j in trial],
            [dofs[j] for j in trial],
            [coords[j] for j in trial],
            "+".join(names[j] for j in trial),
            whole,
        )
        if cand.estimate() < cost + alone[i]:
            group, cost, shared = trial, cand.estimate(), cand
    return None if shared is None else (group, shared)
