"""The spring-constant fitting problem as plain arrays.

For load cases i with free dofs F_i, the model displacement is u_i = K_i^-1 f_i with
K_i = B_i diag(k) B_i^T (B_i: the incidence columns b_e restricted to F_i) and u = 0 on
the constrained dofs. The criterion (docs/design.md, "The G criteria") is

    G(k) = sqrt( sum_i sum_dof w (u_ref,i - u_i)^2 ),

split per load into a free-dof part and ``const`` (the constrained dofs, where u = 0).
Everything an optimiser needs is here; how the network was built is not.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from harness.errors import SpringbenchError
from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
from harness.linalg.shared import SharedSets, best_group
from harness.linalg.sparse import DenseFactor, Factor, nested_dissection
from harness.linalg.stiffness import restriction, stiffness_map, stiffness_pattern
from harness.models.springs import incidence
from harness.optimize.permatrix import network_map, network_values, per_matrix


@dataclass(frozen=True)
class LoadBlock:
    """One load case on its free dofs: B (nfree x e, csc), f, u_ref, w (nfree,), and
    const = sum of w |u_ref|^2 over the constrained dofs; ``dofs``: the free dofs' ids in
    the network (ascending; None: unknown), which lets load sets of one network that hold
    different dofs share a factorisation (harness/linalg/shared.py); ``network``: the
    network's incidence on every dof (B is its rows ``dofs``; None: unknown), whose one map
    k -> K serves every load set and every shared group (:func:`network_map`)."""

    name: str
    B: sp.csc_matrix
    f: np.ndarray
    u_ref: np.ndarray
    w: np.ndarray
    const: float = 0.0
    dofs: np.ndarray | None = None
    network: sp.csc_matrix | None = None


@dataclass(frozen=True)
class ModalTerm:
    """Optional frequency objective: the first len(target) natural frequencies of
    (K - lambda M) on the modal free dofs (B: nfree_m x e, m: diagonal of M there)
    against ``target``, relative error squared, times ``weight``."""

    B: sp.csc_matrix
    m: np.ndarray
    target: np.ndarray
    weight: float = 1.0


@dataclass(frozen=True)
class FitProblem:
    """Blocks + initial constants k0 (e,), optional groups (e,) int (grouped mode: one
    parameter per group, k = k0 * factor[group]) and bounds (lo, hi) as factors of k0.
    ``shared``: load sets that hold different dofs of the network are factorised together
    where that costs fewer flops (:meth:`solve_parts`); the same solutions to rounding, so
    a fit's path and its constants differ at rounding level from the sets apart (False)."""

    blocks: tuple
    k0: np.ndarray
    groups: np.ndarray | None = None
    bounds: tuple = (1e-3, 1e3)
    modal: ModalTerm | None = None
    coords: tuple | None = None  # per block (nfree, dim) dof positions: fill-reducing ordering
    shared: bool = False

    def __post_init__(self):
        k0 = np.asarray(self.k0, float)
        if k0.ndim != 1 or not np.all(np.isfinite(k0)) or np.any(k0 <= 0):
            raise SpringbenchError(
                "k0 must be a 1-D array of positive finite spring constants",
                field="optimizer.k0",
                fix="check the model's stiffness rule",
            )
        e = len(k0)
        for b in self.blocks:
            if (
                b.B.shape[1] != e
                or b.B.shape[0] != len(b.f)
                or len(b.u_ref) != len(b.f)
                or len(b.w) != len(b.f)
            ):
                raise SpringbenchError(
                    f"load '{b.name}': B is {b.B.shape}, f {len(b.f)}, u_ref "
                    f"{len(b.u_ref)}, w {len(b.w)} for {e} springs",
                    field="optimizer.blocks",
                    fix="restrict B, f, u_ref, w to the same free dofs",
                )
        if self.groups is not None:
            g = np.asarray(self.groups)
            if g.shape != (e,) or g.min() < 0:
                raise SpringbenchError(
                    f"groups must be {e} non-negative ints",
                    field="optimizer.groups",
                    fix="one group id per spring",
                )
        lo, hi = self.bounds
        if not (0 < lo <= 1 <= hi):
            raise SpringbenchError(
                f"bounds {self.bounds} must satisfy 0 < lo <= 1 <= hi (factors of k0)",
                field="optimizer.options.bounds",
                fix="e.g. [1e-3, 1e3]",
            )
        object.__setattr__(self, "k0", k0)

    # --- construction -------------------------------------------------------------
    @classmethod
    def from_network(
        cls,
        points,
        springs,
        k0,
        free_masks,
        forces,
        u_ref,
        dof_weights,
        names,
        groups=None,
        bounds=(1e-3, 1e3),
        masses=None,
        freq_target=None,
        freq_weight: float = 0.0,
        modal_free=None,
        extra_columns=None,
    ) -> "FitProblem":
        """Build the blocks from a network: free_masks, forces, u_ref are (L, ndof) with
        dof = dim*node + component; dof_weights (ndof,). The frequency term is used when
        masses and freq_target are given (modal_free: (ndof,) bool, default the first
        load's free dofs). ``extra_columns`` (ndof, m): more rank-one stiffness terms beside
        the springs' (e.g. harness/models/volume.py's), their constants after the springs' in k0."""
        points = np.asarray(points, float)
        B = incidence(points, springs).tocsr()
        if extra_columns is not None:
            B = sp.hstack([B, sp.csr_matrix(extra_columns)]).tocsr()
        ndof = points.size
        free_masks = np.asarray(free_masks, bool).reshape(-1, ndof)
        forces = np.asarray(forces, float).reshape(-1, ndof)
        u_ref = np.asarray(u_ref, float).reshape(-1, ndof)
        w = np.asarray(dof_weights, float).reshape(ndof)
        if not (len(free_masks) == len(forces) == len(u_ref) == len(names)):
            raise SpringbenchError(
                f"{len(names)} names, {len(free_masks)} free masks, {len(forces)} forces, "
                f"{len(u_ref)} references",
                field="optimizer.loads",
                fix="one row per load case",
            )
        blocks, coords = [], []
        cache, network = {}, B.tocsc()
        X = np.repeat(points, points.shape[1], axis=0)
        for name, free, f, ur in zip(names, free_masks, forces, u_ref):
            key = free.tobytes()
            if key not in cache:  # identical free sets share one B (the optimisers group on it)
                cache[key] = (B[free].tocsc(), X[free], np.flatnonzero(free))
            fixed = ~free
            blocks.append(
                LoadBlock(
                    str(name),
                    cache[key][0],
                    f[free].copy(),
                    ur[free].copy(),
                    w[free].copy(),
                    float(np.sum(w[fixed] * ur[fixed] ** 2)),
                    cache[key][2],
                    network,
                )
            )
            coords.append(cache[key][1])
        modal = None
        if masses is not None and freq_target is not None and len(freq_target) > 0:
            mfree = free_masks[0] if modal_free is None else np.asarray(modal_free, bool)
            dim = points.shape[1]
            mdof = np.repeat(np.asarray(masses, float), dim)
            modal = ModalTerm(
                B[mfree].tocsc(), mdof[mfree], np.asarray(freq_target, float), float(freq_weight)
            )
        return cls(
            tuple(blocks),
            np.asarray(k0, float),
            None if groups is None else np.asarray(groups, int),
            tuple(bounds),
            modal,
            tuple(coords),
        )

    def with_reference(self, u_ref, const=None) -> "FitProblem":
        """The same network, loads and weights with another reference: ``u_ref`` is one
        free-dof array per block (``const`` per block, default 0: the reference is zero on
        the constrained dofs). Shares B and the load sets' cached orderings and symbolic
        factorisations, so a second reference on one network costs no new setup."""
        const = [0.0] * len(self.blocks) if const is None else list(const)
        if len(u_ref) != len(self.blocks) or len(const) != len(self.blocks):
            raise SpringbenchError(
                f"{len(u_ref)} references for {len(self.blocks)} load blocks",
                field="optimizer.u_ref",
                fix="one free-dof array per load block",
            )
        blocks = []
        for b, u, c in zip(self.blocks, u_ref, const):
            u = np.asarray(u, float)
            if u.shape != b.f.shape:
                raise SpringbenchError(
                    f"load '{b.name}': reference has shape {u.shape}, free dofs {b.f.shape}",
                    field="optimizer.u_ref",
                    fix="restrict the reference to the block's free dofs",
                )
            blocks.append(dataclasses.replace(b, u_ref=u.copy(), const=float(c)))
        new = dataclasses.replace(self, blocks=tuple(blocks))
        sets = self.__dict__.get("_sets")
        if sets is not None:
            moved = []
            for s in sets:
                s = copy.copy(s)  # keeps the cached stiffness map and symbolic factorisation
                s.Uref = np.stack([blocks[i].u_ref for i in s.index], 1)
                s.const = float(sum(blocks[i].const for i in s.index))
                moved.append(s)
            object.__setattr__(new, "_sets", moved)
        return new

    # --- parameters ------------------------------------------------------------------
    @property
    def n_springs(self) -> int:
        return len(self.k0)

    @property
    def n_params(self) -> int:
        return self.n_springs if self.groups is None else int(np.max(self.groups)) + 1

    def k_of(self, factors: np.ndarray) -> np.ndarray:
        """Spring constants from per-parameter factors of k0 (per spring or per group)."""
        factors = np.asarray(factors, float)
        return self.k0 * (factors if self.groups is None else factors[self.groups])

    # --- the reference evaluation ---------------------------------------------------
    def load_sets(self) -> list["LoadSet"]:
        """Blocks grouped by identical B (same free dofs): one K, one factorisation.
        Computed once (with the orderings) and cached on the instance."""
        cached = self.__dict__.get("_sets")
        if cached is None:
            cached = load_sets(self)
            object.__setattr__(self, "_sets", cached)
        return cached

    def solve_parts(self) -> list[tuple[list, SharedSets | None]]:
        """The load sets (indices into :meth:`load_sets`) in groups factorised together: with
        ``shared``, the sets that hold different dofs of one network share one factorisation
        (harness/linalg/shared.py) where it costs fewer flops than theirs apart; else each
        set alone. Cached."""
        cached = self.__dict__.get("_parts")
        if cached is None:
            sets = self.load_sets()
            cached = solve_parts(sets) if self.shared else [([i], None) for i in range(len(sets))]
            object.__setattr__(self, "_parts", cached)
        return cached

    def prepare(self) -> None:
        """Build the network's map k -> K now (:func:`network_map`): a pool of fits forked
        after it shares it (the answer is the same either way)."""
        for network in {id(b.network): b.network for b in self.blocks}.values():
            if network is not None:
                network_map(network)

    def solvers(self, k):
        """(load sets, solver) per group of :meth:`solve_parts` at k: the solver maps one
        right-hand side block per set to its solution block; one fresh factorisation each.
        Nothing here keeps a solver once yielded: a caller that drops it before the next
        one (``del``) holds one factorisation at a time, not two."""
        for j in range(len(self.solve_parts())):
            yield self.solver_of(j, k)

    def solver_of(self, j: int, k):
        """(load sets, solver) of group j of :meth:`solve_parts` at k (as :meth:`solvers`)."""
        sets, k = self.load_sets(), np.asarray(k, float)
        idx, shared = self.solve_parts()[j]
        group = [sets[i] for i in idx]
        return group, (shared.factor(k).solve if shared is not None else _each(group[0], k))

    def solve(self, k) -> list[np.ndarray]:
        """Free-dof displacements per load by a fresh sparse factorisation (shared by
        loads with identical free dofs, and by load sets of :meth:`solve_parts`)."""
        out = [None] * len(self.blocks)
        for group, solve in self.solvers(k):
            for s, U in zip(group, solve([s.F for s in group])):
                for j, i in enumerate(s.index):
                    out[i] = U[:, j]
            del solve  # its factorisation, before the next one
        return out

    def G(self, k) -> float:
        """G (docs/design.md, "The G criteria") by full re-solve (the reference implementation)."""
        return float(np.sqrt(self.G2(k)))

    def G2(self, k) -> float:
        total = 0.0
        for b, u in zip(self.blocks, self.solve(k)):
            d = b.u_ref - u
            total += float(d @ (b.w * d)) + b.const
        return total

    def G_ref_norm(self) -> float:
        """sqrt(sum w |u_ref|^2): the normaliser of the normalised G (docs/design.md,
        "The G criteria")."""
        return float(np.sqrt(sum(float(b.u_ref @ (b.w * b.u_ref)) + b.const for b in self.blocks)))


@dataclass
class LoadSet:
    """Loads sharing one free-dof set: B, the block indices, and column-stacked F, Uref,
    W (nfree, L); ``perm`` is the fill-reducing order of SuperLU (None: its own). What
    depends on B alone (the map k -> K, the orderings) is kept per matrix
    (:func:`per_matrix`), so problems on subsets of the same blocks share it."""

    B: sp.csc_matrix
    index: list
    F: np.ndarray
    Uref: np.ndarray
    W: np.ndarray
    const: float
    name: str
    coords: np.ndarray | None = None
    k0: np.ndarray | None = None  # the constants the ordering's pattern is built from
    dofs: np.ndarray | None = None  # the free dofs' ids in the network (LoadBlock.dofs)
    key: str = ""  # B's content digest
    network: sp.csc_matrix | None = None  # LoadBlock.network

    @property
    def perm(self) -> np.ndarray | None:
        """Nested dissection by the coordinates (above 2,000 dofs), else None."""
        if self.coords is None or self.B.shape[0] <= 2000:
            return None
        return per_matrix(
            self.B, "perm", lambda: nested_dissection(stiffness(self.B, self.k0), self.coords)
        )

    def stiffness(self, k) -> sp.csc_matrix:
        """K = B diag(k) B^T as one sparse product with a precomputed map k -> K.data: the
        network's (:func:`network_map`) restricted to the set's dofs when it is known, else
        the set's own."""
        k = np.asarray(k, float)
        if self.network is None or self.dofs is None:
            pattern, kmap = per_matrix(self.B, "kmap", lambda: stiffness_map(self.B))
            data = kmap @ k
        else:
            whole = network_map(self.network)[0]
            pattern, gather = per_matrix(self.B, "gather", lambda: restriction(whole, self.dofs))
            data = network_values(self.network, k)[gather]
        K = pattern.copy()
        K.data = data
        return K

    def factor(self, k, kind: str = "auto"):
        """A solver for K(k): dense Cholesky for small blocks; else "multifrontal"
        (nested-dissection Cholesky, best in 3-D and for many right-hand sides) or
        "superlu" (SuperLU in nested-dissection order, best for single solves in 2-D).
        "auto" picks multifrontal in 3-D, SuperLU in 2-D."""
        if self.B.shape[0] <= DENSE_FACTOR_MAX:
            return DenseFactor(self.stiffness(k).toarray(), self.name)
        if kind == "auto":
            kind = (
                "multifrontal"
                if self.coords is not None and self.coords.shape[1] == 3
                else "superlu"
            )
        # above DENSE_FACTOR_MAX: 1,680 dofs, 24
        if kind == "multifrontal" and self.coords is not None:
            # right-hand sides: factor + solve 30 ms, SuperLU (minimum degree) 99 ms
            return MultifrontalCholesky(self.stiffness(k), self.symbolic(), self.name)
        return Factor(self.stiffness(k), self.perm, self.name)

    def symbolic(self) -> Symbolic:
        """The multifrontal ordering and fronts of K's pattern (kept per matrix; from the
        pattern alone, so a set only estimated never builds its map k -> K)."""
        return per_matrix(
            self.B, "symbolic", lambda: Symbolic(stiffness_pattern(self.B), self.coords)
        )


def _each(load_set: "LoadSet", k: np.ndarray):
    """The solver of one load set's fresh factorisation at k (for :meth:`FitProblem.solvers`)."""
    fac = load_set.factor(k)
    return lambda rhs: [fac.solve(r).reshape(r.shape) for r in rhs]


DENSE_FACTOR_MAX = 400


def _key(B: sp.csc_matrix):
    h = hashlib.sha1()
    for a in (np.asarray(B.shape), B.indptr, B.indices, B.data):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def load_sets(problem: FitProblem) -> list[LoadSet]:
    groups: dict = {}
    for i, b in enumerate(problem.blocks):
        key = id(b.B)
        groups.setdefault(key, []).append(i)
    merged: dict = {}
    for key, idx in groups.items():  # blocks built separately but equal: merge too
        merged.setdefault(_key(problem.blocks[idx[0]].B), []).extend(idx)
    out = []
    for key, idx in merged.items():
        idx = sorted(idx)
        bl = [problem.blocks[i] for i in idx]
        B = bl[0].B.tocsc()
        out.append(
            LoadSet(
                B,
                idx,
                np.stack([b.f for b in bl], 1),
                np.stack([b.u_ref for b in bl], 1),
                np.stack([b.w for b in bl], 1),
                float(sum(b.const for b in bl)),
                "+".join(b.name for b in bl),
                None if problem.coords is None else problem.coords[idx[0]],
                problem.k0,
                bl[0].dofs,
                key,
                bl[0].network,
            )
        )
    return out


def solve_parts(sets: list[LoadSet]) -> list[tuple[list, SharedSets | None]]:
    """:meth:`FitProblem.solve_parts` of ``sets``: among the sets above the dense size
    whose dofs are known, the group that shares a factorisation (harness/linalg/shared.py
    best_group; kept per matrix)."""
    idx = [
        i
        for i, s in enumerate(sets)
        if s.dofs is not None and s.coords is not None and s.B.shape[0] > DENSE_FACTOR_MAX
    ]
    found = None
    network = sets[idx[0]].network if idx else None
    whole = None
    if network is not None:
        whole = (lambda: network_map(network)[0], lambda k: network_values(network, k))
    if len(idx) >= 2:
        h = hashlib.sha1()
        for i in idx:
            h.update(sets[i].key.encode())
            h.update(np.ascontiguousarray(sets[i].dofs, np.int64).tobytes())
        found = per_matrix(
            sets[idx[0]].B,
            f"shared:{h.hexdigest()}",
            lambda: best_group(
                [sets[i].B for i in idx],
                [sets[i].dofs for i in idx],
                [sets[i].coords for i in idx],
                [sets[i].symbolic().estimate()["gflop"] for i in idx],
                [sets[i].name for i in idx],
                whole,
            ),
        )
    if found is None:
        return [([i], None) for i in range(len(sets))]
    group = [idx[j] for j in found[0]]
    return [(group, found[1])] + [([i], None) for i in range(len(sets)) if i not in group]


def stiffness(B: sp.csc_matrix, k: np.ndarray) -> sp.csc_matrix:
    """K = B diag(k) B^T on a block's free dofs."""
    return (B.multiply(k[None, :]) @ B.T).tocsc()
