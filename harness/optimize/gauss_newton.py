"""Gauss-Newton (Levenberg-Marquardt) over x = log k: the residual r = sqrt(W) (u_ref - u)
of all loads, its Jacobian applied by adjoint products (one factorisation per load set,
reused by every product) and the normal equations solved by CG (harness/optimize/gradient.py
derives the products); far faster than L-BFGS-B on large networks (``springbench bench fit``)."""

from __future__ import annotations

import time

import numpy as np

from harness.optimize.deadline import deadline as limit
from harness.optimize.gradient import start_point
from harness.optimize.options import check_options, static_only
from harness.optimize.problem import FitProblem, value_and_grad

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
    import scipy.sparse.linalg as spla_

    opts = check_options(options, GN_DEFAULTS, "gauss-newton")
    static_only(problem, "gauss-newton")
    t0 = time.perf_counter()
    cap = limit(opts, "the gauss-newton fit")
    lo, hi = np.log(problem.bounds[0]), np.log(problem.bounds[1])
    npar = problem.n_params
    groups = problem.groups

    def expand(v):
        return v if groups is None else v[groups]

    def reduce(g):
        return g if groups is None else np.bincount(groups, weights=g, minlength=npar)

    x, init_info = start_point(problem, opts["init"])
    Jc = _Jacobian(problem, problem.k_of(np.exp(x)))
    G0sq = Jc.G2 if opts["init"] == "none" else value_and_grad(problem, problem.k0, grad=False)[0]
    trace = [(0, np.sqrt(G0sq))] + ([] if opts["init"] == "none" else [(0, np.sqrt(Jc.G2))])
    if Jc.G2 > G0sq:  # a start worse than k0: fall back to k0
        x, Jc = np.zeros(npar), _Jacobian(problem, problem.k0)
        init_info["init_rejected"] = True
    mu = None
    stop, nit, n_solves, done_its = "maxiter", 0, 0, 0
    for nit in range(1, int(opts["maxiter"]) + 1):
        if opts["target"] > 0 and Jc.G2 <= (opts["target"] ** 2) * G0sq:
            stop = "target"
            break
        cap.check()
        r = Jc.residual()
        g = reduce(Jc.rmatvec(r))
        rng = np.random.default_rng([seed, nit])
        if opts["probes"] > 0:  # Hutchinson estimate of diag(J^T J)
            diag = np.zeros(npar)
            for _ in range(int(opts["probes"])):
                diag += reduce(Jc.rmatvec(rng.choice([-1.0, 1.0], size=len(r)))) ** 2
            diag /= opts["probes"]
            diag = np.maximum(diag, 1e-12 * diag.max())
        else:
            diag = np.ones(npar)
        if mu is None:
            mu = mu0 = opts["mu"] * float(np.mean(diag))
        A = spla_.LinearOperator(
            (npar, npar),
            dtype=float,
            matvec=lambda v: reduce(Jc.rmatvec(Jc.matvec(expand(v)))) + mu * v,
        )
        Minv = spla_.LinearOperator((npar, npar), dtype=float, matvec=lambda v: v / (diag + mu))
        rtol = float(opts["cg_rtol"])  # fixed: a loose Eisenstat-Walker forcing term did worse here
        p, _ = spla_.cg(
            A,
            -g,
            rtol=rtol,
            maxiter=int(opts["cg_maxiter"]),
            callback=lambda xk: cap.check(),
            M=Minv,
        )
        # model decrease of G^2/2
        pred = -(g @ p) - 0.5 * (float(np.sum(Jc.matvec(expand(p)) ** 2)))
        n_solves += Jc.n_solves
        # backtrack before giving up
        for t in (1.0, 0.25, 1 / 16):
            cap.check()
            xn = np.clip(x + t * p, lo, hi)
            Jn = _Jacobian(problem, problem.k_of(np.exp(xn)))
            if Jn.G2 < Jc.G2:
                break
        actual = 0.5 * (Jc.G2 - Jn.G2)
        if actual > 0:
            small = 2 * max(actual, pred) <= float(opts["ftol"]) * Jc.G2
            x, Jc = xn, Jn
            rho = actual / max(pred, 1e-300)
            mu *= 1 / 3 if (t == 1.0 and rho > 0.75) else (1.0 if t == 1.0 and rho > 0.25 else 4.0)
        else:
            mu *= 16.0
            small = mu > 1e12 * mu0
        if small:
            stop = "converged"
        trace.append((nit, np.sqrt(Jc.G2)))
        done_its = nit
        if status is not None:
            status(
                f"gauss-newton it {nit} of {int(opts['maxiter'])} G/G0={np.sqrt(Jc.G2 / G0sq):.3g}"
            )
        if stop == "converged":
            break
    k = problem.k_of(np.exp(x))
    G_final = float(np.sqrt(Jc.G2))  # from a fresh factorisation at k (no incremental state)
    return dict(
        k=k,
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
