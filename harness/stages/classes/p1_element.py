"""A material per element for linear tetrahedra (2-D: triangles): the fit of model class "p1",
for engines that take one (E, nu) per tetrahedron (NVIDIA Newton's k_mu, k_lambda per tet).

Each element e has two parameters, theta_e = (q_e, s_e) = (log M_e, log(1 + a_e / mu_e)),
where a = lambda (plane stress: 2 lambda mu / (lambda + 2 mu)) and M = a + 2 mu is the
element's P-wave modulus: mu = M / (e^s + 1), a = M tanh(s / 2). Both are logs, so the prior
and L-BFGS-B see one scale: q is the element's stiffness, s its compressibility (3-D:
s = -log(1 - 2 nu), 0 at nu = 0, log 10 at nu = 0.45). (log E, nu) would put nu near 0.5 on
a scale a thousand times steeper than log E; log(a / mu) has no value at nu = 0.

The box: q_e <= q(E, nu) and 0 <= s_e <= s(E, nu), the case's material. No element is
stiffer (M bounds the wave speed, so an explicit engine's stable time step is never smaller
than with the plain material, and the stress a float32 engine makes of rounded positions
is never larger) or nearer incompressible than the material the engine already runs: the
export asks nothing of the engine that the plain (E, nu) does not. Without the box the fit
drove elements at nu = 0.49 to nu' = 0.499 and M' to 21 M, which float32 Newton could not
settle; M' <= M alone settles it, nu' <= nu keeps it 4x closer there (docs/engines.md).

Objective: the balanced misfit of p1-global over the training states (each fitted load's
weighted squared error over its reference norm squared, harness/stages/classes/p1_global.py
``Training``) plus PRIOR_WEIGHT x L x sum_e (V_e / V) |theta_e - theta_case|^2 over the L
fitted loads: in the objective's own units (a load's whole reference norm is 1), a uniform
step of one unit in q and s away from the case's material costs as much as a relative error
of sqrt(PRIOR_WEIGHT) = 3.2 % on every fitted load, whatever their number. Where the data
say little (elements the loads barely strain, combinations they cannot tell apart) the
element stays near the case's material. Gradient by the adjoint (K symmetric: one
factorisation per constraint set gives u and the adjoint lambda): dJ/da_e =
-V_e (B lambda)_e^T D_a (B u)_e, the same with D_mu. scipy L-BFGS-B from the case's
material with a fixed iteration count and tolerances (no wall clock).

The fitted row is exported only when its validation loads' score beats the plain P1's
(harness/stages/sms_accept.py ``judge``, as p1-global), else the plain P1 (``choice``
"rule"). Its network carries the elements' E and nu in ``info`` (``E_elements``,
``nu_elements``; ``E_effective`` / ``nu_effective`` only when every element shares one
pair, else NaN), which harness/export/model_json.py writes per tetrahedron."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import minimize

from harness.models.p1 import P1Term, strain_matrices
from harness.models.volume import volumes
from harness.stages.classes.p1 import P1Class
from harness.stages.classes.p1_global import (
    NU_MAX,
    Training,
    coefficients,
    constants,
    judged,
    material_fit_runs,
    training,
    unit_tensors,
)
from harness.stages.sms_measures import scored_columns

METHOD = "l-bfgs-b"
MAXITER = 300  # L-BFGS-B iterations (each: one factorisation per constraint set and step)
FTOL, GTOL = 1e-12, 1e-10  # its relative objective decrease and projected gradient tolerances
PRIOR_WEIGHT = 1e-3  # per fitted load per unit of (q, s) deviation, volume-weighted


@dataclass(frozen=True, eq=False)
class ElementSplit:
    """Per element e: V_e B_e^T D_a B_e and V_e B_e^T D_mu B_e (m, nd, nd), their global
    dofs, the strain matrices B (m, nv, nd), volumes V (m,) and D_a, D_mu: K(a, mu) =
    sum_e a_e K_a^e + mu_e K_mu^e is one sparse assembly of element-scaled blocks."""

    Ka: np.ndarray
    Kmu: np.ndarray
    rows: np.ndarray
    B: np.ndarray
    V: np.ndarray
    D_a: np.ndarray
    D_mu: np.ndarray
    ndof: int
    plane_stress: bool

    @classmethod
    def of(cls, points, elements, plane: str = "stress") -> ElementSplit:
        points = np.asarray(points, float)
        e = np.asarray(elements, int)
        n, dim = points.shape
        B = strain_matrices(points, e)
        V = np.abs(volumes(points, e))
        D_a, D_mu = unit_tensors(dim)
        Ka = np.einsum("m,mvi,vw,mwj->mij", V, B, D_a, B)
        Kmu = np.einsum("m,mvi,vw,mwj->mij", V, B, D_mu, B)
        rows = (e[:, :, None] * dim + np.arange(dim)).reshape(len(e), -1)
        return cls(Ka, Kmu, rows, B, V, D_a, D_mu, n * dim, dim == 2 and plane == "stress")

    def stiffness(self, a: np.ndarray, mu: np.ndarray) -> sp.csc_matrix:
        data = a[:, None, None] * self.Ka + mu[:, None, None] * self.Kmu
        nd = self.rows.shape[1]
        r = np.repeat(self.rows[:, :, None], nd, axis=2)
        c = np.repeat(self.rows[:, None, :], nd, axis=1)
        return sp.csc_matrix((data.ravel(), (r.ravel(), c.ravel())), shape=(self.ndof,) * 2)

    def strains(self, u: np.ndarray) -> np.ndarray:
        """(L, m, nv) Voigt strains of displacements u (L, ndof)."""
        return np.einsum("mvk,lmk->lmv", self.B, u[:, self.rows])


def lame_of(theta: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """(a, mu) per element of theta = (q (m,), s (m,)) stacked."""
    M, s = np.exp(theta[:m]), theta[m:]
    return M * np.tanh(0.5 * s), M / (np.exp(s) + 1)


def theta_of(E, nu, plane_stress: bool) -> tuple[float, float]:
    """(q, s) of one pair (E, nu)."""
    a, mu = coefficients(float(E), float(nu), plane_stress)
    return math.log(a + 2 * mu), math.log1p(a / mu)


def pairs_of(a, mu, plane_stress: bool) -> tuple[np.ndarray, np.ndarray]:
    """(E, nu) per element of (a, mu): a / mu = 2 nu / (1 - nu) in plane stress, else
    2 nu / (1 - 2 nu)."""
    r = np.asarray(a, float) / np.asarray(mu, float)
    nu = r / (2 + r) if plane_stress else r / (2 * (1 + r))
    return 2 * mu * (1 + nu), nu


def misfit(split: ElementSplit, t: Training, theta: np.ndarray) -> tuple[float, np.ndarray]:
    """(J, dJ/dtheta): the balanced misfit sum_l sum_dofs w (u - u_ref)^2 of the P1 statics
    with the elements' theta, and its gradient by the adjoint."""
    m = len(split.V)
    a, mu = lame_of(theta, m)
    K = split.stiffness(a, mu)
    u = np.zeros_like(t.forces)
    lam = np.zeros_like(t.forces)
    groups: dict = {}
    for i, free in enumerate(t.free):
        groups.setdefault(free.tobytes(), []).append(i)
    for idx in groups.values():
        fd = np.flatnonzero(t.free[idx[0]])
        lu = spla.splu(K[fd][:, fd].tocsc())
        u[np.ix_(idx, fd)] = lu.solve(t.forces[idx][:, fd].T).T
        r = 2 * t.w[idx] * (u[idx] - t.u_ref[idx])
        lam[np.ix_(idx, fd)] = lu.solve(r[:, fd].T).T
    J = float(np.sum(t.w * (u - t.u_ref) ** 2))
    eu, el = split.strains(u), split.strains(lam)
    g_a = -split.V * np.einsum("lmv,vw,lmw->m", el, split.D_a, eu)
    g_mu = -split.V * np.einsum("lmv,vw,lmw->m", el, split.D_mu, eu)
    ds = mu / (1 + np.exp(-theta[m:]))  # d mu / ds = -ds, d a / ds = 2 ds
    return J, np.concatenate([mu * g_mu + a * g_a, ds * (2 * g_a - g_mu)])


@dataclass(frozen=True)
class ElementFit:
    """The fitted (E, nu) per element, the data misfit sqrt(J) at the start and the end,
    the prior weight used (absolute), iterations, evaluations and the stop message."""

    E: np.ndarray
    nu: np.ndarray
    misfit_initial: float
    misfit_final: float
    weight: float
    nit: int
    nfev: int
    stop: str


def fit_elements(split: ElementSplit, t: Training, E0, nu0, prior: float, start=None):
    """:class:`ElementFit` from the case's (E0, nu0), the prior's centre, with weight
    ``prior`` x the number of fitted loads, in the box of the module's docstring (``start``:
    another (E, nu) to start from, e.g. p1-global's pair, moved into the box)."""
    m = len(split.V)
    nu0 = min(max(float(nu0), 0.0), NU_MAX)
    q0, s0 = theta_of(E0, nu0, split.plane_stress)
    centre = np.repeat([q0, s0], m)
    x0 = centre if start is None else np.repeat(theta_of(*start, split.plane_stress), m)
    x0 = np.clip(x0, np.repeat([-np.inf, 0.0], m), centre)
    v = np.tile(split.V / split.V.sum(), 2)
    w = float(prior) * len(t.forces)

    def f(x):
        J, g = misfit(split, t, x)
        d = x - centre
        return J + w * float(v @ (d * d)), g + 2 * w * v * d

    bounds = [(None, q0)] * m + [(0.0, s0)] * m
    opts = {"maxiter": MAXITER, "maxfun": 2 * MAXITER, "ftol": FTOL, "gtol": GTOL}
    res = minimize(f, x0, jac=True, method="L-BFGS-B", bounds=bounds, options=opts)
    E, nu = pairs_of(*lame_of(res.x, m), split.plane_stress)
    Jx = misfit(split, t, x0)[0]
    return ElementFit(
        E,
        nu,
        math.sqrt(Jx),
        math.sqrt(misfit(split, t, res.x)[0]),
        w,
        int(res.nit),
        int(res.nfev),
        str(res.message),
    )


def with_elements(base, E, nu, plane: str = "stress"):
    """``base`` (a P1 network, harness/models/p1.py) with (E_e, nu_e) on element e; its
    ``info`` holds them and the pair they share (NaN when they differ)."""
    E, nu = np.asarray(E, float), np.asarray(nu, float)
    a, mu = coefficients(E, nu, base.dim == 2 and plane == "stress")
    D_a, D_mu = unit_tensors(base.dim)
    D = a[:, None, None] * D_a + mu[:, None, None] * D_mu
    term = P1Term.build(base.points, base.volume.elements, D)
    one = bool(np.all(E == E[0]) and np.all(nu == nu[0]))
    pair = (float(E[0]), float(nu[0])) if one else (math.nan, math.nan)
    net = base.with_k(
        base.k,
        stiffness="p1",
        E_effective=pair[0],
        nu_effective=pair[1],
        E_elements=E,
        nu_elements=nu,
    )
    return dataclasses.replace(net, volume=term)


def optimise(setting, run_, base, first):
    """(the fitted row, its network, no trace): the fit of (E_e, nu_e), exported when the
    validation loads accept it, else the plain P1 (``first``: its row)."""
    s, mat = setting, setting.case.material
    s.ctx.status(f"p1: fitting E and nu per element ({METHOD})")
    t0 = time.perf_counter()
    split = ElementSplit.of(base.points, base.volume.elements, mat.plane)
    fit = fit_elements(split, training(s, base), mat.E, mat.nu, PRIOR_WEIGHT)
    seconds = time.perf_counter() - t0
    net = with_elements(base, fit.E, fit.nu, mat.plane)
    tag = f"p1-{METHOD}"
    net, res, sc, sh, choice, g_fit, verdict = judged(s, base, net, first, tag)
    columns = s.fit_columns(
        first,
        "p1",
        METHOD,
        sc,
        grouped=False,
        seconds=seconds,
        G_final_optimizer=fit.misfit_final,
        G_initial_optimizer=fit.misfit_initial,
        objective="G",
        budget=f"maxiter={MAXITER}",
        n_params=2 * len(fit.E),
    )
    row = {
        **columns.row(s.common),
        "opt_nit": fit.nit,
        "opt_nfev": fit.nfev,
        "opt_stop": fit.stop,
        "opt_prior": PRIOR_WEIGHT,
        "choice": choice,
        "G_norm_fit": g_fit,
        "E_fit_min": float(fit.E.min()),
        "E_fit_max": float(fit.E.max()),
        "nu_fit_min": float(fit.nu.min()),
        "nu_fit_max": float(fit.nu.max()),
        "_tag": tag,
        **verdict.columns,
        **constants(net),
    }
    row.update(scored_columns(s.case, sc, sh, first), **s.validated(net, res))
    return row, net, None


@dataclass(frozen=True)
class P1ElementClass(P1Class):
    """P1 with the case's material (its rule "p1") and, when the case runs an optimiser on
    G (whatever its method), with a material fitted per element."""

    def fit_runs(self, runs: list[dict]) -> list[dict]:
        return material_fit_runs(runs, METHOD)

    def fit(self, setting, run: dict, start, first: dict):
        return optimise(setting, run, start, first)


P1 = P1ElementClass("p1")
