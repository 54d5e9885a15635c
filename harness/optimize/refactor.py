"""G by a full re-solve of every proposal (the paper's cost): the baseline engine of
simulated annealing beside the incremental one (harness/optimize/incremental.py)."""

from __future__ import annotations

import numpy as np

from harness.optimize.problem import FitProblem


class RefactorG:
    """The paper's way: every proposal re-assembles and re-factorises K for each load
    set. Same interface as IncrementalG; the baseline of ``bench sa``. Best effort: each
    load set's fastest solver of the project (``LoadSet.factor(kind="multifrontal")``:
    nested-dissection multifrontal Cholesky above 2,000 dofs -- measured 1.5-2x faster
    than SuperLU in nested-dissection order on the 2-D grids and 2-3x on the 3-D ones --,
    SuperLU or dense Cholesky below)."""

    mode = "refactor"

    def __init__(self, problem: FitProblem, k, **_):
        self.problem = problem
        self.k = np.array(k, float)
        self._G = self.G_of(self.k)
        self._pending = None
        self.upcoming = np.empty(0, int)
        self.n_rebase = 0

    def G_of(self, k) -> float:
        G2 = 0.0
        for ls in self.problem.load_sets():
            U = ls.factor(k, kind="multifrontal").solve(ls.F).reshape(ls.F.shape)
            D = ls.Uref - U
            G2 += float(np.sum(D * (ls.W * D))) + ls.const
        return float(np.sqrt(max(G2, 0.0)))

    def G(self) -> float:
        return self._G

    def propose_k(self, k_new_vec) -> float:
        G = self.G_of(k_new_vec)
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
