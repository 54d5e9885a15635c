"""Gradient fits of the spring constants: adjoint gradient + L-BFGS-B, and Nelder-Mead
for grouped mode (Gauss-Newton on the same adjoint products: harness/optimize/gauss_newton.py).

Adjoint gradient. Per load, G_i^2 = d^T W d + const with d = u_ref - u, K u = f,
K = sum_e k_e b_e b_e^T. Differentiating K u = f gives K du/dk_e = -b_e (b_e.u), so

    dG^2/dk_e = -2 (W d)^T du/dk_e = 2 (W d)^T K^-1 b_e (b_e.u) = 2 (lambda.b_e)(b_e.u),

with the adjoint K lambda = W d (K symmetric): one factorisation and two solves per load
set (forward and adjoint), then B^T lambda and B^T u give all e components at once.

Frequency term (optional). For K phi = mu M phi with M-normalised phi,
dmu/dk_e = (phi.b_e)^2; the natural frequency is f = sqrt(mu) / (2 pi), so
df/dk_e = (phi.b_e)^2 / (8 pi^2 f). The term is weight * sum_j (f_j / f*_j - 1)^2.

The objective minimised is Phi = G^2 / G(k0)^2 (+ the frequency term), over log factors of
k0 (per spring, or per group in grouped mode), so it is unit-free and k stays positive.

Prior (option ``prior``, weight a >= 0). Phi += a * mean_e log(k_e / k0_e)^2: a pull of
every constant towards its start (the stiffness rule's). Displacements of a few loads do
not determine tens of thousands of constants; unregularised, L-BFGS-B drifts along the
nearly flat directions of G and the constants memorise the fitted loads (held-out
loads got worse while the fitted ones improved). Both terms are dimensionless and
intensive (a mean over springs, G relative to its start), so a weight carries across
meshes: a = 1 prices an RMS log-deviation of 1 (a factor e) like the whole initial misfit.

Conditioning. A change of k with wavelength lambda changes the nodal forces like
1/lambda (a divergence) and the displacements like lambda (K^-1 smooths twice), so the
Gauss-Newton matrix J^T J acts like an inverse Laplacian on k: its condition number grows
like (network size / spacing)^2 and L-BFGS-B / CG need many solves to fix short-wavelength
constants, to which G is nearly blind. The equation error (equilibrium.py) sees them
directly; ``init = "equilibrium-gap"`` starts lbfgs / gauss-newton from its estimate.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.optimize as so
import scipy.sparse.linalg as spla

from harness.errors import SpringbenchError
from harness.optimize.deadline import deadline as limit
from harness.optimize.equilibrium import equilibrium_gap_factors
from harness.optimize.evaluation import value_and_grad
from harness.optimize.options import check_options
from harness.optimize.problem import FitProblem, stiffness

LBFGS_DEFAULTS = dict(
    maxiter=15000,  # L-BFGS-B iterations
    maxfun=None,  # function evaluations (None: 1.25 * maxiter)
    max_seconds=None,  # wall-time cap: passing it aborts (harness/optimize/deadline.py)
    target=0.0,  # stop when G / G(k0) <= target
    memory=20,  # L-BFGS history length (scipy's maxcor)
    gtol=0.0,  # projected-gradient tolerance on Phi = G^2/G0^2 (+ freq term)
    ftol=0.0,  # relative decrease tolerance of Phi
    init="none",  # start point: "none" (k0) or "equilibrium-gap" (equilibrium.py)
    scale=0.5,  # diagonal scaling of log k by (spring tension^2 at k0)^-scale; 0: none
    prior=0.0,  # weight a of the prior a * mean_e log(k_e/k0_e)^2 (see above); 0: none
    x0=None,  # start point log(k/k0) per parameter (a multi-start's other starts); None: by init
)

NM_DEFAULTS = dict(
    maxiter=None,  # Nelder-Mead iterations (None: 400 * parameters)
    max_seconds=None,  # as lbfgs's
    xatol=1e-10,  # simplex size in log k
    fatol=0.0,  # objective spread (on Phi)
    target=0.0,
    prior=0.0,  # as lbfgs's
)


def tension_scaling(problem: FitProblem, tension2: np.ndarray, power: float) -> np.ndarray:
    """Diagonal scaling d of the parameters (x = d y) from the squared spring tensions t_e^2
    at k0: d = (mean / t^2)^power per parameter, clipped to [1/20, 20]. Since
    du/dlog k_e = -K^-1 b_e t_e, the curvature of G^2 along log k_e is t_e^2 |K^-1 b_e|^2:
    with the second factor taken as constant, power 1/2 is a Jacobi scaling, so weakly
    loaded springs get longer steps."""
    e = (
        tension2
        if problem.groups is None
        else np.bincount(problem.groups, weights=tension2, minlength=problem.n_params)
    )
    m = float(np.mean(e))
    if power == 0 or m <= 0:
        return np.ones(problem.n_params)
    return np.clip((m / np.maximum(e, 1e-12 * m)) ** power, 1 / 20, 20.0)


def frequencies(problem: FitProblem, k: np.ndarray, vectors: bool = False):
    """The first len(target) natural frequencies (Hz) of the modal term, ascending."""
    mt = problem.modal
    K = stiffness(mt.B, np.asarray(k, float))
    nk = len(mt.target)
    n = K.shape[0]
    if n <= 600 or nk >= n - 1:
        import scipy.linalg as sla

        minv = 1.0 / np.sqrt(mt.m)
        A = (K.toarray() * minv[:, None]) * minv[None, :]
        mu, V = sla.eigh(A, subset_by_index=[0, nk - 1])
        phi = V * minv[:, None]
    else:
        import scipy.sparse as sp

        # seeded start
        mu, phi = spla.eigsh(
            K,
            k=nk,
            M=sp.diags(mt.m),
            sigma=0.0,
            which="LM",
            v0=np.random.default_rng(0).standard_normal(K.shape[0]),
        )
        o = np.argsort(mu)
        mu, phi = mu[o], phi[:, o]
        phi = phi / np.sqrt(np.sum(phi * phi * mt.m[:, None], axis=0))[None, :]
    f = np.sqrt(np.maximum(mu, 0.0)) / (2 * np.pi)
    return (f, phi) if vectors else f


def freq_term_and_grad(problem: FitProblem, k: np.ndarray):
    """weight * sum (f/f* - 1)^2 and its gradient w.r.t. k."""
    mt = problem.modal
    f, phi = frequencies(problem, k, vectors=True)
    rel = f / mt.target - 1.0
    val = mt.weight * float(rel @ rel)
    dfdk = (mt.B.T @ phi) ** 2 / (8 * np.pi**2 * np.maximum(f, 1e-300))[None, :]
    grad = mt.weight * (dfdk @ (2.0 * rel / mt.target))
    return val, grad


class Objective:
    """Phi(x) = G^2/G0^2 (+ frequency term) over x = log(k/k0) per parameter, with its
    gradient; remembers the best point and stops at a target. ``deadline`` (a
    :class:`harness.optimize.deadline.Deadline`, or None) is checked before each
    evaluation: passing it aborts the fit. ``from_k0``: the fit starts at k0, so G^2's
    gradient there is computed with G0 and the first evaluation reuses both (the same
    numbers a second solve would give, one factorisation fewer)."""

    def __init__(
        self,
        problem: FitProblem,
        target: float = 0.0,
        deadline=None,
        prior: float = 0.0,
        from_k0: bool = False,
    ):
        self.p = problem
        self.prior = float(prior)
        self.tension2 = np.zeros(problem.n_springs)  # squared spring tensions at k0 (for scalings)
        self.G0sq, g0 = value_and_grad(problem, problem.k0, grad=from_k0, tension2=self.tension2)
        self._at_k0 = (self.G0sq, g0) if from_k0 else None
        if self.G0sq <= 0:
            raise SpringbenchError(
                "G(k0) = 0: nothing to fit",
                field="optimizer",
                fix="check the reference displacements",
            )
        self.target, self.deadline = target, deadline
        self.n_eval = 0
        self.phi0 = 1.0  # Phi at k0: k0 is a point seen (a start elsewhere may be worse)
        if problem.modal is not None and problem.modal.weight > 0:
            self.phi0 += freq_term_and_grad(problem, problem.k0)[0]
        self.best = (self.phi0, np.zeros(problem.n_params), float(np.sqrt(self.G0sq)))
        self.trace = []

    def k(self, x):
        return self.p.k_of(np.exp(x))

    def __call__(self, x, grad=True):
        if self.deadline is not None:
            self.deadline.check()
        k = self.k(x)
        if self._at_k0 is not None and not np.any(x):  # k is k0 exactly
            G2, g = self._at_k0
            self._at_k0 = None
        else:
            G2, g = value_and_grad(self.p, k, grad)
        phi = G2 / self.G0sq
        gk = g / self.G0sq if grad else None
        if self.p.modal is not None and self.p.modal.weight > 0:
            fv, fg = freq_term_and_grad(self.p, k)
            phi += fv
            if grad:
                gk = gk + fg
        if self.prior > 0:
            pv, pg = prior_term(self.p, x, self.prior)
            phi += pv
        self.n_eval += 1
        G = float(np.sqrt(max(G2, 0.0)))
        self.trace.append((self.n_eval, G))
        if phi < self.best[0]:
            self.best = (phi, np.array(x), G)
        if not grad:
            return phi
        gx = gk * k
        if self.prior > 0:
            gx = gx + pg
        if self.p.groups is not None:
            gx = np.bincount(self.p.groups, weights=gx, minlength=self.p.n_params)
        return phi, gx

    def done(self) -> str | None:
        if self.target > 0 and self.best[2] <= self.target * np.sqrt(self.G0sq):
            return "target"
        return None


def prior_term(problem: FitProblem, x: np.ndarray, weight: float):
    """weight * mean over springs of log(k/k0)^2 and its gradient per spring (e,) in x =
    log(k/k0) (grouped mode: x per group, each spring counted; summed per group later)."""
    xe = np.asarray(x, float) if problem.groups is None else np.asarray(x, float)[problem.groups]
    n = problem.n_springs
    return weight * float(xe @ xe) / n, (2.0 * weight / n) * xe


# what scipy's L-BFGS-B means by a status whose detail it leaves empty (scipy >= 1.15 says
# "ABNORMAL: " where the Fortran code said ABNORMAL_TERMINATION_IN_LNSRCH)
SCIPY_DETAILS = {
    "ABNORMAL": "the line search found no step that lowers the objective "
    "(ABNORMAL_TERMINATION_IN_LNSRCH): "
    "rounding dominates the objective's changes, or its gradient disagrees with it",
    "ERROR": "invalid input to L-BFGS-B",
    "WARNING": "stopped on a warning",
}


def scipy_stop(res) -> str:
    """The whole of scipy's stop message: ``scipy: STATUS: detail``, with the detail filled
    in where scipy leaves it empty."""
    msg = str(res.message).strip()
    status, _, detail = msg.partition(":")
    if not detail.strip():
        msg = f"{status}: {SCIPY_DETAILS.get(status, 'no detail given')}"
    return f"scipy: {msg}"


def _result(obj: Objective, t0: float, stop: str, nit: int, extra: dict) -> dict:
    x = obj.best[1]
    k = obj.k(x)
    G_final = obj.best[2]  # evaluated by a fresh factorisation at k
    info = dict(stop=stop, iterations=nit, evaluations=obj.n_eval, phi=float(obj.best[0]), **extra)
    if obj.p.modal is not None:
        f = frequencies(obj.p, k)
        info["frequencies"] = f.tolist()
        info["freq_rel_error"] = (f / obj.p.modal.target - 1).tolist()
    return dict(
        k=k,
        G_initial=float(np.sqrt(obj.G0sq)),
        G_final=G_final,
        trace=np.array([(0, np.sqrt(obj.G0sq))] + obj.trace),
        seconds=time.perf_counter() - t0,
        n_steps=obj.n_eval,
        accepted=nit,
        info=info,
    )


class _Stop(Exception):
    pass


def lbfgs(problem: FitProblem, options: dict, seed: int = 0, status=None, deadline=None) -> dict:
    """L-BFGS-B over log(k/k0) with the problem's bounds, in variables y = x / d scaled by the
    spring tensions at k0 (option ``scale``, see tension_scaling); deterministic (seed unused).
    It stops by maxiter, maxfun, gtol, ftol or target; ``deadline`` (a cap shared by several
    fits; None: the option max_seconds) only aborts (harness/optimize/deadline.py)."""
    opts = check_options(options, LBFGS_DEFAULTS, "lbfgs")
    t0 = time.perf_counter()
    cap = limit(opts, "the lbfgs fit", deadline)
    at_k0 = opts["init"] == "none" and (opts["x0"] is None or not np.any(opts["x0"]))
    obj = Objective(problem, opts["target"], cap, opts["prior"], from_k0=at_k0)
    x0, init_info = start_point(problem, opts["init"])
    lo, hi = problem.bounds
    n = problem.n_params
    if opts["x0"] is not None:
        x0 = np.clip(np.asarray(opts["x0"], float).reshape(n), np.log(lo), np.log(hi))
    nit = [0]

    def cb(xk):
        nit[0] += 1
        if status is not None and nit[0] % 10 == 0:
            status(f"lbfgs it {nit[0]} of {int(opts['maxiter'])} G={obj.best[2]:.4g}")
        if obj.done():
            raise _Stop

    d = tension_scaling(problem, obj.tension2, float(opts["scale"]))  # x = d y
    first = None
    if opts["x0"] is not None:
        first = (x0 / d, *obj(x0))
    elif opts["init"] != "none":
        first = (x0 / d, *obj(x0))
        if first[1] > obj.phi0:  # the start is worse than k0: start from k0 instead
            x0, first = np.zeros(n), None
            init_info["init_rejected"] = True

    def fun(y):
        nonlocal first
        if first is not None and np.array_equal(y, first[0]):  # scipy's first call: known
            phi, gx = first[1:]
            first = None
        else:
            if obj.done():
                raise _Stop
            phi, gx = obj(d * y)
        if obj.done() == "target":  # no need to wait for the next call
            raise _Stop
        return phi, d * gx

    stop = None
    try:
        res = so.minimize(
            fun,
            x0 / d,
            jac=True,
            method="L-BFGS-B",
            callback=cb,
            bounds=list(zip(np.log(lo) / d, np.log(hi) / d)),
            options=dict(
                maxiter=int(opts["maxiter"]),
                maxfun=int(opts["maxfun"] or 1.25 * opts["maxiter"]),
                maxcor=int(opts["memory"]),
                gtol=float(opts["gtol"]),
                ftol=float(opts["ftol"]),
            ),
        )
        stop = scipy_stop(res)
    except _Stop:
        stop = obj.done()
    return _result(
        obj, t0, stop, nit[0], {"init": opts["init"], "prior": float(opts["prior"]), **init_info}
    )


def nelder_mead(problem: FitProblem, options: dict, seed: int = 0, status=None) -> dict:
    """Nelder-Mead over log group factors (grouped mode, few parameters); derivative-free,
    so it also serves as an independent check of the gradient fits."""
    opts = check_options(options, NM_DEFAULTS, "nelder-mead")
    if problem.n_params > 50:
        raise SpringbenchError(
            f"nelder-mead with {problem.n_params} parameters is hopeless",
            field="optimizer.method",
            fix="use grouped mode (groups) or method = 'lbfgs'",
        )
    t0 = time.perf_counter()
    cap = limit(opts, "the nelder-mead fit")
    obj = Objective(problem, opts["target"], cap, opts["prior"])
    lo, hi = problem.bounds
    n = problem.n_params

    def fun(x):
        if obj.done():
            raise _Stop
        return obj(x, grad=False)

    nit = [0]

    def cb(xk):
        nit[0] += 1

    stop = None
    try:
        res = so.minimize(
            fun,
            np.zeros(n),
            method="Nelder-Mead",
            callback=cb,
            bounds=[(np.log(lo), np.log(hi))] * n,
            options=dict(
                maxiter=int(opts["maxiter"] or 400 * n),
                maxfev=int(opts["maxiter"] or 400 * n) * 2,
                xatol=float(opts["xatol"]),
                fatol=float(opts["fatol"]),
                adaptive=n > 4,
            ),
        )
        stop = scipy_stop(res)
    except _Stop:
        stop = obj.done()
    return _result(obj, t0, stop, nit[0], {"prior": float(opts["prior"])})


INITS = ("none", "equilibrium-gap")


def start_point(problem: FitProblem, init: str):
    """x0 = log(k/k0) per parameter for option ``init``, and info about how it was found."""
    if init not in INITS:
        raise SpringbenchError(
            f"unknown init '{init}'",
            field="optimizer.options.init",
            fix=f"use one of {list(INITS)}",
        )
    if init == "none":
        return np.zeros(problem.n_params), {}
    x, info = equilibrium_gap_factors(problem)
    return np.log(x), info
