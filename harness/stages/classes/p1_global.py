"""One effective isotropic material (E', nu') for linear tetrahedra (2-D: triangles) on the
model's cells (model class "p1-global"): the answer to "what do I type into my engine" for
engines that take one (E, nu) per body (MuJoCo flex, PhysX, Drake, Newton's tetrahedra).

Coarse P1 is too stiff (it locks as nu nears 0.5), so the case's own (E, nu) is a poor
choice there. The class scores the plain P1 with the case's material (its one rule, "p1")
and fits (E', nu') so the P1 statics match the reference on the fitted loads: the training
states' relative misfits, each load's G normalised by its own reference norm (as the springs'
balanced objective, harness/optimize/select.py ``balanced``), minimised over log E' and nu' in
[0, NU_MAX] by scipy's bounded trust-region least squares with an exact Jacobian and a fixed
evaluation count and tolerances (no wall clock). P1 stiffness is linear in the Lame constants,
so K(E', nu') = a K_a + mu K_mu is assembled from two matrices made once (a = lambda; plane
stress: 2 lambda mu / (lambda + 2 mu)); each evaluation factorises it once per constraint set.

The fitted row is exported only when it beats the plain P1 on the case's validation loads
(harness/stages/sms_accept.py ``judge``; none: the fit stands), else it carries the plain P1
(``choice`` "rule"). Rows carry ``E_effective`` and ``nu_effective`` (the exported pair)."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import least_squares

from harness.case.elasticity import lame
from harness.mechanics import statics
from harness.models.p1 import P1Term, strain_matrices
from harness.models.volume import volumes
from harness.scoring import node_weights
from harness.stages.classes.p1 import P1Class
from harness.stages.sms_accept import judge
from harness.stages.sms_measures import scored_columns

METHOD = "least-squares"
MAX_NFEV = 60  # evaluations of the fit (each: one factorisation per constraint set)
TOL = 1e-12  # ftol, xtol and gtol of the fit
NU_MAX = 0.499  # the fit's upper bound on nu' (lambda' stays finite)


@dataclass(frozen=True, eq=False)
class LameSplit:
    """K(E, nu) = a(E, nu) K_a + mu(E, nu) K_mu of P1 on fixed cells (n*dim square):
    ``plane_stress`` uses a = 2 lambda mu / (lambda + 2 mu), else a = lambda."""

    K_a: sp.csc_matrix
    K_mu: sp.csc_matrix
    plane_stress: bool

    def coefficients(self, E: float, nu: float) -> tuple[float, float]:
        """(a, mu) of (E, nu)."""
        return coefficients(E, nu, self.plane_stress)

    def derivatives(self, E: float, nu: float) -> tuple[tuple, tuple]:
        """((da, dmu) / d log E, (da, dmu) / d nu): the Jacobian's directions."""
        if self.plane_stress:
            da = E * (1 + nu * nu) / (1 - nu * nu) ** 2
        else:
            da = E * (1 + 2 * nu * nu) / ((1 + nu) * (1 - 2 * nu)) ** 2
        return self.coefficients(E, nu), (da, -E / (2 * (1 + nu) ** 2))

    def stiffness(self, E: float, nu: float) -> sp.csc_matrix:
        a, mu = self.coefficients(E, nu)
        return (a * self.K_a + mu * self.K_mu).tocsc()


def coefficients(E: float, nu: float, plane_stress: bool) -> tuple[float, float]:
    """(a, mu) of (E, nu): a = lambda, or in plane stress 2 lambda mu / (lambda + 2 mu)."""
    if plane_stress:
        return E * nu / (1 - nu * nu), E / (2 * (1 + nu))
    return lame(E, nu)


def unit_tensors(dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(D_a, D_mu) in Voigt order (engineering shear): D = a D_a + mu D_mu, D_a = m m^T
    (m: 1 on the normal strains), D_mu = diag(2 on the normal strains, 1 on the shears)."""
    normal = np.arange(3 if dim == 2 else 6) < dim
    m = normal.astype(float)
    return np.outer(m, m), np.diag(np.where(normal, 2.0, 1.0))


def lame_split(points, elements, plane: str = "stress") -> LameSplit:
    """The two P1 matrices of :class:`LameSplit` on the simplices ``elements``:
    sum_e |V_e| B_e^T D B_e with D each of :func:`unit_tensors`."""
    points = np.asarray(points, float)
    e = np.asarray(elements, int)
    n, dim = points.shape
    B = strain_matrices(points, e)
    V = np.abs(volumes(points, e))
    rows = (e[:, :, None] * dim + np.arange(dim)).reshape(len(e), -1)
    r = np.repeat(rows[:, :, None], rows.shape[1], axis=2)
    c = np.repeat(rows[:, None, :], rows.shape[1], axis=1)

    def assemble(D):
        Ke = np.einsum("m,mvi,vw,mwj->mij", V, B, D, B)
        return sp.csc_matrix((Ke.ravel(), (r.ravel(), c.ravel())), shape=(n * dim, n * dim))

    D_a, D_mu = unit_tensors(dim)
    return LameSplit(assemble(D_a), assemble(D_mu), dim == 2 and plane == "stress")


@dataclass(frozen=True, eq=False)
class Training:
    """The fitted loads as arrays (L, ndof): free dofs, forces, reference displacements and
    each load's dof weights divided by its reference's weighted norm squared (balanced)."""

    free: np.ndarray
    forces: np.ndarray
    u_ref: np.ndarray
    w: np.ndarray

    @classmethod
    def of(cls, free, forces, u_ref, w_nodes) -> Training:
        """``u_ref`` (L, n, dim); ``w_nodes`` (n,) the node weights."""
        L, n, dim = np.shape(u_ref)
        u = np.asarray(u_ref, float).reshape(L, n * dim)
        w = np.repeat(np.asarray(w_nodes, float), dim)
        r2 = (u * u) @ w
        scale = np.where(r2 > 0, 1.0 / np.where(r2 > 0, r2, 1.0), 1.0)
        return cls(np.asarray(free, bool), np.asarray(forces, float), u, scale[:, None] * w)


def _solves(split: LameSplit, t: Training, E: float, nu: float) -> tuple:
    """(u (L, ndof), du/d(log E, nu) (2, L, ndof)) of the P1 statics with (E, nu)."""
    (a, mu), (da_nu, dmu_nu) = split.derivatives(E, nu)
    K = a * split.K_a + mu * split.K_mu
    u = np.zeros_like(t.forces)
    du = np.zeros((2, *t.forces.shape))
    groups: dict = {}
    for i, free in enumerate(t.free):
        groups.setdefault(free.tobytes(), []).append(i)
    for idx in groups.values():
        fd = np.flatnonzero(t.free[idx[0]])
        lu = spla.splu(K[fd][:, fd].tocsc())
        U = lu.solve(t.forces[idx][:, fd].T)  # (free dofs, loads)
        u[np.ix_(idx, fd)] = U.T
        full = np.zeros((len(t.forces[0]), len(idx)))
        full[fd] = U
        dK_nu = (da_nu * (split.K_a @ full) + dmu_nu * (split.K_mu @ full))[fd]
        du[0][np.ix_(idx, fd)] = -U.T  # dK/dlogE = K: du = -u
        du[1][np.ix_(idx, fd)] = -lu.solve(dK_nu).T
    return u, du


@dataclass(frozen=True)
class PairFit:
    """The fitted (E, nu), the misfit sqrt(sum of the loads' normalised G^2) at the start
    and at the end, the evaluations made and the fit's stop message."""

    E: float
    nu: float
    misfit_initial: float
    misfit_final: float
    nfev: int
    stop: str


def fit_pair(split: LameSplit, t: Training, E0: float, nu0: float, fix_nu: bool = False):
    """:class:`PairFit` of (E', nu') from (E0, nu0) (``fix_nu``: E' alone, nu' = nu0)."""
    sw = np.sqrt(t.w)
    start = np.array([math.log(E0), min(max(nu0, 0.0), NU_MAX)])
    on = [0] if fix_nu else [0, 1]  # the fitted parameters of (log E, nu)
    cache: dict = {}

    def at(x):
        full = start.copy()
        full[on] = x
        key = full.tobytes()
        if key not in cache:
            cache.clear()
            u, du = _solves(split, t, math.exp(full[0]), float(full[1]))
            cache[key] = ((sw * (u - t.u_ref)).ravel(), (sw * du).reshape(2, -1).T[:, on], full)
        return cache[key]

    r0 = float(np.linalg.norm(at(start[on])[0]))
    res = least_squares(
        lambda x: at(x)[0],
        start[on],
        jac=lambda x: at(x)[1],
        bounds=(np.array([-np.inf, 0.0])[on], np.array([np.inf, NU_MAX])[on]),
        method="trf",
        x_scale=1.0,
        ftol=TOL,
        xtol=TOL,
        gtol=TOL,
        max_nfev=MAX_NFEV,
    )
    full = at(res.x)[2]
    misfit = float(np.linalg.norm(res.fun))
    return PairFit(math.exp(full[0]), float(full[1]), r0, misfit, int(res.nfev), str(res.message))


def with_pair(base, E: float, nu: float, plane: str = "stress"):
    """``base`` (a P1 network, harness/models/p1.py) with one isotropic (E, nu) on every
    element, the pair in its ``info``."""
    a, mu = coefficients(E, nu, base.dim == 2 and plane == "stress")
    D_a, D_mu = unit_tensors(base.dim)
    D = a * D_a + mu * D_mu
    el = base.volume.elements
    term = P1Term.build(base.points, el, np.broadcast_to(D, (len(el), *D.shape)))
    net = base.with_k(base.k, stiffness="p1", E_effective=float(E), nu_effective=float(nu))
    return dataclasses.replace(net, volume=term)


def training(setting, base) -> Training:
    """The setting's fitted loads as :class:`Training` arrays on ``base``'s dofs."""
    s = setting
    _, free, forces = statics.all_load_arrays(base, s.case)
    return Training.of(
        free[s.fit], forces[s.fit], s.u_ref[s.fit], node_weights(base.classes, s.weights)
    )


def optimise(setting, run_, base, first):
    """(the fitted row, its network, no trace): the fit of (E', nu'), exported when the
    validation loads accept it, else the plain P1 (``first``: its row)."""
    s, m = setting, setting.case.material
    s.ctx.status(f"p1-global: fitting E and nu ({METHOD})")
    t0 = time.perf_counter()
    split = lame_split(base.points, base.volume.elements, m.plane)
    fit = fit_pair(split, training(s, base), m.E, m.nu)
    seconds = time.perf_counter() - t0
    net = with_pair(base, fit.E, fit.nu, m.plane)
    tag = f"p1-global-{METHOD}"
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
        budget=f"max_nfev={MAX_NFEV}",
        n_params=2,
    )
    row = {
        **columns.row(s.common),
        "opt_nfev": fit.nfev,
        "opt_stop": fit.stop,
        "choice": choice,
        "G_norm_fit": g_fit,
        "E_fit": fit.E,
        "nu_fit": fit.nu,
        "_tag": tag,
        **verdict.columns,
        **constants(net),
    }
    row.update(scored_columns(s.case, sc, sh, first), **s.validated(net, res))
    return row, net, None


def judged(s, base, net, first, tag: str) -> tuple:
    """(network, statics, fitted score, held-out score, choice, the fit's G_norm, verdict):
    the fitted material ``net`` where the validation loads accept it over the plain P1
    ``base`` (its row ``first``), else ``base`` ("rule"); the exported one written as
    ``tag``."""
    res, sc, sh = s.evaluate(net)
    val = s.validated(net, res).get("G_val_mean", math.nan)
    verdict = judge(val, {"p1": first.get("G_val_mean", math.nan)})
    choice, g_fit = "fit", sc.G_norm
    if verdict.best is not None and not verdict.accepted:
        net, choice = base, "rule"
        res, sc, sh = s.evaluate(net)
    s.write(net, res, tag)
    return net, res, sc, sh, choice, g_fit, verdict


def material_fit_runs(runs: list[dict], method: str) -> list[dict]:
    """A fitted material's one fit run (``method``) when the case fits G at all."""
    if not any(r["objective"] == "G" and r["method"] != "none" for r in runs):
        return []
    return [dict(method=method, options={}, objective="G", where="optimizer.method")]


def constants(net) -> dict:
    """E_effective (Pa) and nu_effective of a network (NaN: not one isotropic pair)."""
    return {
        "E_effective": float(net.info.get("E_effective", math.nan)),
        "nu_effective": float(net.info.get("nu_effective", math.nan)),
    }


@dataclass(frozen=True)
class P1GlobalClass(P1Class):
    """P1 with the case's material (its rule "p1") and with one fitted (E', nu')."""

    def build(self, case, spec: dict, seed: int = 0):
        net = super().build(case, spec, seed)
        m = case.material
        uniform = m.fibre is None and not m.regions
        pair = (m.E, m.nu) if uniform else (math.nan, math.nan)
        return net.with_k(net.k, E_effective=float(pair[0]), nu_effective=float(pair[1]))

    def rules(self, spec: dict) -> list[str]:
        return ["p1"]

    def fit_runs(self, runs: list[dict]) -> list[dict]:
        return material_fit_runs(runs, METHOD)

    def fit(self, setting, run: dict, start, first: dict):
        return optimise(setting, run, start, first)

    def constants(self, net) -> dict:
        return constants(net)


P1_GLOBAL = P1GlobalClass("p1-global")
