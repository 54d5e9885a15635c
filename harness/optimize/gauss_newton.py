"""Gauss-Newton (Levenberg-Marquardt) over x = log k: the residual r = sqrt(W) (u_ref - u)
of all loads, its Jacobian applied by adjoint products (one factorisation per load set,
reused by every product) and the normal equations solved by CG (harness/optimize/gradient.py
derives the products); far faster than L-BFGS-B on large networks (``springbench bench fit``)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from harness.optimize.deadline import deadline as limit
from harness.optimize.evaluation import value_and_grad
from harness.optimize.gradient import start_point
from harness.optimize.options import check_options, static_only
from harness.optimize.problem import FitProblem

GN_DEFAULTS = dict(
    maxiter=200,  # outer (Levenberg-Marquardt) iterations
    cg_maxiter=200,  # inner CG iterations on the normal equations per outer step
    cg_rtol=0.01,  # inner relative residual of CG
    mu=1e-4,  # initial damping, relative to the mean diagonal of J^T J
    probes=0,  # random probes for a Jacobi preconditioner diag(J^T J) ~ E[(J^T z)^2]; 0: none
    # (it did not help on grid networks, hence off; nor did the spring-tension
    # Jacobi estimate that helps lbfgs: fewer solves, same G per solve)
    max_seconds=None,  # wall-time cap: passing it aborts (harness/optimize/deadline.py)
    target=0.0,  # stop when G / G(k0) <= target
    init="none",  # start point: "none" (k0) or "equilibrium-gap" (equilibrium.py)
    ftol=1e-8,  # converged (as MINPACK's lmder): an accepted step lowers G^2, and its model
    # predicts, by less than ftol * G^2; or the damping exceeds 1e12 x its start
)


class _Jacobian:
    """Residual r = sqrt(W) (u_ref - u) of all loads and products with its Jacobian with
    respect to x = log k, at one k (one factorisation per load set, reused by every
    product): J v = sqrt(W) K^-1 B (k v B^T u),  J^T y = sum_l k (B^T u_l)(B^T K^-1 sqrt(W) y_l)."""

    def __init__(self, problem: FitProblem, k):
        self.p, self.k = problem, k
        self.parts = []
        G2 = 0.0
        for s in problem.load_sets():
            fac = s.factor(k)
            U = fac.solve(s.F).reshape(s.F.shape)
            sw = np.sqrt(s.W)
            R = sw * (s.Uref - U)
            G2 += float(np.sum(R * R)) + s.const
            self.parts.append((s, fac, sw, s.B.T @ U, R))
        self.G2 = G2
        self.n_solves = 0

    def residual(self):
        return np.concatenate([R.ravel() for *_, R in self.parts])

    def matvec(self, v):
        kv = self.k * v
        out = []
        for s, fac, sw, BtU, _ in self.parts:
            X = fac.solve(s.B @ (kv[:, None] * BtU)).reshape(s.B.shape[0], BtU.shape[1])
            out.append((sw * X).ravel())
            self.n_solves += 1
        return np.concatenate(out)

    def rmatvec(self, y):
        g = np.zeros(len(self.k))
        pos = 0
        for s, fac, sw, BtU, R in self.parts:
            Y = y[pos : pos + R.size].reshape(R.shape)
            pos += R.size
            Lam = fac.solve(sw * Y).reshape(R.shape)
            g += np.sum((s.B.T @ Lam) * BtU, axis=1)
            self.n_solves += 1
        return self.k * g


def gauss_newton(problem: FitProblem, options: dict, seed: int = 0, status=None) -> dict:
    """Levenberg-Marquardt over x = log(k/k0) with CG on the normal equations (J^T J +
    mu I) p = -J^T r: G is a least-squares norm, so Gauss-Newton uses its structure where
    L-BFGS only sees a scalar; on recoverable problems (zero residual) it converges fast.
    Each CG step costs one forward and one adjoint solve per load set with the kept
    factorisation. Grouped mode sums the Jacobian columns of a group. It stops by maxiter,
    ftol (converged) or target; max_seconds only aborts (harness/optimize/deadline.py)."""
    opts = check_options(options, GN_DEFAULTS, "gauss-newton")
    static_only(problem, "gauss-newton")
    t0 = time.perf_counter()
    lm = _LM(problem, opts, limit(opts, "the gauss-newton fit"), seed)
    x, Jc, G0sq, trace, init_info = _start(problem, opts)
    mu = mu0 = None
    stop, n_solves, done_its = "maxiter", 0, 0
    for nit in range(1, int(opts["maxiter"]) + 1):
        if opts["target"] > 0 and Jc.G2 <= (opts["target"] ** 2) * G0sq:
            stop = "target"
            break
        lm.cap.check()
        g = lm.reduce(Jc.rmatvec(Jc.residual()))
        diag = lm.diagonal(Jc, nit)
        if mu is None:
            mu = mu0 = opts["mu"] * float(np.mean(diag))
        p = lm.direction(Jc, g, diag, mu)
        # model decrease of G^2/2
        pred = -(g @ p) - 0.5 * (float(np.sum(Jc.matvec(lm.expand(p)) ** 2)))
        n_solves += Jc.n_solves
        xn, Jn, t = lm.backtrack(x, p, Jc)
        actual = 0.5 * (Jc.G2 - Jn.G2)
        if actual > 0:
            small = 2 * max(actual, pred) <= float(opts["ftol"]) * Jc.G2
            x, Jc = xn, Jn
            mu *= _damping_factor(t, actual / max(pred, 1e-300))
        else:
            mu *= 16.0
            small = mu > 1e12 * mu0
        trace.append((nit, np.sqrt(Jc.G2)))
        done_its = nit
        if status is not None:
            status(
                f"gauss-newton it {nit} of {int(opts['maxiter'])} G/G0={np.sqrt(Jc.G2 / G0sq):.3g}"
            )
        if small:
            stop = "converged"
            break
    G_final = float(np.sqrt(Jc.G2))  # from a fresh factorisation at k (no incremental state)
    return dict(
        k=problem.k_of(np.exp(x)),
        G_initial=float(np.sqrt(G0sq)),
        G_final=G_final,
        trace=np.array(trace),
        seconds=time.perf_counter() - t0,
        n_steps=done_its,
        accepted=done_its,
        info=dict(
            stop=stop,
            iterations=done_its,
            solves=n_solves + Jc.n_solves,
            mu=mu,
            init=opts["init"],
            **init_info,
        ),
    )


def _start(problem: FitProblem, opts: dict):
    """(x, its Jacobian, G(k0)^2, the trace's first points, the start's info): the start
    point of ``init``, or k0 when that start is worse than k0."""
    x, init_info = start_point(problem, opts["init"])
    Jc = _Jacobian(problem, problem.k_of(np.exp(x)))
    G0sq = Jc.G2 if opts["init"] == "none" else value_and_grad(problem, problem.k0, grad=False)[0]
    trace = [(0, np.sqrt(G0sq))] + ([] if opts["init"] == "none" else [(0, np.sqrt(Jc.G2))])
    if Jc.G2 > G0sq:  # a start worse than k0: fall back to k0
        x, Jc = np.zeros(problem.n_params), _Jacobian(problem, problem.k0)
        init_info["init_rejected"] = True
    return x, Jc, G0sq, trace, init_info


def _damping_factor(t: float, rho: float) -> float:
    """The damping's change after an accepted step of length t whose actual decrease is rho
    times the predicted one: down on a full good step, up on a poor or shortened one."""
    return 1 / 3 if (t == 1.0 and rho > 0.75) else (1.0 if t == 1.0 and rho > 0.25 else 4.0)


@dataclass(frozen=True)
class _LM:
    """The parts of one Levenberg-Marquardt fit: the problem, its options, the wall-time
    cap and the seed of the diagonal's probes."""

    problem: FitProblem
    opts: dict
    cap: object
    seed: int

    def expand(self, v):
        """Per-group values as per-spring ones."""
        return v if self.problem.groups is None else v[self.problem.groups]

    def reduce(self, g):
        """Per-spring values summed over each group."""
        groups, npar = self.problem.groups, self.problem.n_params
        return g if groups is None else np.bincount(groups, weights=g, minlength=npar)

    def diagonal(self, Jc: _Jacobian, nit: int) -> np.ndarray:
        """The Jacobi preconditioner's diag(J^T J): ``probes`` Hutchinson probes, or ones."""
        npar, probes = self.problem.n_params, self.opts["probes"]
        if probes <= 0:
            return np.ones(npar)
        rng = np.random.default_rng([self.seed, nit])
        size = Jc.residual().size
        diag = np.zeros(npar)
        for _ in range(int(probes)):
            diag += self.reduce(Jc.rmatvec(rng.choice([-1.0, 1.0], size=size))) ** 2
        diag /= probes
        return np.maximum(diag, 1e-12 * diag.max())

    def direction(self, Jc: _Jacobian, g, diag, mu: float) -> np.ndarray:
        """The step p of (J^T J + mu I) p = -g by preconditioned CG."""
        import scipy.sparse.linalg as spla_

        npar = self.problem.n_params
        A = spla_.LinearOperator(
            (npar, npar),
            dtype=float,
            matvec=lambda v: self.reduce(Jc.rmatvec(Jc.matvec(self.expand(v)))) + mu * v,
        )
        Minv = spla_.LinearOperator((npar, npar), dtype=float, matvec=lambda v: v / (diag + mu))
        rtol = float(self.opts["cg_rtol"])  # fixed: a loose Eisenstat-Walker forcing term did worse
        p, _ = spla_.cg(
            A,
            -g,
            rtol=rtol,
            maxiter=int(self.opts["cg_maxiter"]),
            callback=lambda xk: self.cap.check(),
            M=Minv,
        )
        return p

    def backtrack(self, x, p, Jc: _Jacobian):
        """(x, Jacobian, step length) of the first of the steps 1, 1/4, 1/16 along p that
        lowers G (the last one tried if none does)."""
        problem = self.problem
        lo, hi = np.log(problem.bounds[0]), np.log(problem.bounds[1])
        for t in (1.0, 0.25, 1 / 16):
            self.cap.check()
            xn = np.clip(x + t * p, lo, hi)
            Jn = _Jacobian(problem, problem.k_of(np.exp(xn)))
            if Jn.G2 < Jc.G2:
                break
        return xn, Jn, t
