"""Static equilibrium of the nonlinear models (springs, B&C elements) under a Loading
(harness.mechanics.dynamics holds their forces, Jacobians and time stepping).

- ``solve_static``: Newton with load stepping and a backtracking line search.
- ``solve_static_path``: the same, then pseudo-arclength continuation where load stepping
  stalls: it follows the equilibrium path through a limit point (the tangent stiffness
  turns singular and the load factor has to decrease: a snap-through of the model, not a
  solver failure) and reports it in a one-line status.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from harness.errors import SimulationError
from harness.mechanics.dynamics import Loading, _solve_regularised, stiffness

# -- statics --------------------------------------------------------------------------------


def solve_static(
    model,
    loading: Loading,
    *,
    load_steps: int = 5,
    tol: float = 1e-9,
    max_iter: int = 30,
    x0=None,
    max_cuts: int = 8,
) -> np.ndarray:
    """Equilibrium positions f_int(x) + lambda f_ext = 0 on the free dofs, lambda raised in
    ``load_steps`` increments to 1 (an increment whose Newton iteration fails is halved, up
    to ``max_cuts`` times); Newton on K = -df/dx with a backtracking line search on |r|."""
    x = np.array(model.points if x0 is None else x0, float)
    free = np.repeat(~loading.fixed, 3)
    ext = loading.external()
    graph = model.node_graph()
    scale = max(np.abs(ext).max(), 1e-300)
    lam, dlam, cuts = 0.0, 1.0 / load_steps, 0
    while lam < 1.0:
        target = min(1.0, lam + dlam)
        y, ok, res = _newton(model, graph, x, free, target * ext, tol * scale, max_iter)
        if ok:
            x, lam = y, target
            continue
        cuts += 1
        if cuts > max_cuts:
            raise SimulationError(
                f"Newton did not converge at load factor {target:g} (|r| = {res:.3g} N)",
                fix="use more load_steps, or check that the body is held",
            )
        dlam /= 2
    return x


@dataclass(frozen=True)
class StaticPath:
    """Result of :func:`solve_static_path`: ``x`` the equilibrium at the full load (None if
    not reached), ``load_factor`` the highest load factor reached, ``folds`` the load
    factors at which the path turned back (limit points), ``status`` one line, ``x_limit``
    the equilibrium nearest the first limit point (None without one)."""

    x: np.ndarray | None
    load_factor: float
    folds: tuple
    status: str
    x_limit: np.ndarray | None = None


def solve_static_path(
    model,
    loading: Loading,
    *,
    load_steps: int = 5,
    tol: float = 1e-9,
    max_iter: int = 12,
    max_cuts: int = 2,
    arc_steps: int = 150,
) -> StaticPath:
    """Static equilibrium at the full load: load stepping as :func:`solve_static`; where an
    increment cannot converge even when cut ``max_cuts`` times, pseudo-arclength
    continuation (:func:`arclength`) from the last equilibrium for up to ``arc_steps``
    steps. Never raises for a stalled path: the status says what happened."""
    x = np.array(model.points, float)
    free = np.repeat(~loading.fixed, 3)
    ext = loading.external()
    graph = model.node_graph()
    # |r| <= tol |f_ext|, but not below the rounding of the internal forces (~ eps k L)
    k_max = float(np.abs(stiffness(model).diagonal()).max())
    size = float(np.ptp(model.points, axis=0).max())
    scale = max(np.abs(ext).max(), 1e3 * np.finfo(float).eps * k_max * size / tol, 1e-300)
    lam, dlam, cuts = 0.0, 1.0 / load_steps, 0
    while lam < 1.0 and cuts <= max_cuts:
        target = min(1.0, lam + dlam)
        y, ok, _ = _newton(model, graph, x, free, target * ext, tol * scale, max_iter)
        if ok:
            x, lam = y, target
        else:
            cuts += 1
            dlam /= 2
    if lam >= 1.0:
        return StaticPath(x, 1.0, (), "converged (load stepping)")
    path = arclength(model, graph, x, lam, free, ext, tol * scale, steps=arc_steps)
    folds = tuple(path["folds"])
    where = ", ".join(f"{f:.4g}" for f in folds)
    if path["x"] is not None:
        status = (
            f"converged past limit point(s) at load factor {where} (snap-through of the model)"
            if folds
            else "converged (continuation)"
        )
        return StaticPath(path["x"], 1.0, folds, status, path["x_limit"])
    if folds:
        status = (
            f"limit point at load factor {folds[0]:.4g}: the tangent stiffness turns "
            "singular and the "
            "equilibrium path turns back (a snap-through instability of the model, not a "
            "solver failure); "
            f"full load not regained in {arc_steps} continuation steps (load factor now "
            f"{path['lam']:.3g})"
        )
    else:
        status = (
            f"stalled at load factor {path['lam_max']:.4g} (no limit point found: {path['why']})"
        )
    return StaticPath(None, float(path["lam_max"]), folds, status, path["x_limit"])


def _lu(model, free, y):
    """The sparse LU of the tangent stiffness at y on the free dofs."""
    return spla.splu(stiffness(model, y)[free][:, free].tocsc())


@dataclass(frozen=True)
class _Path:
    """The continuation's problem: the model, its free dofs, the external force (f on the
    free dofs) and c, the displacement per unit load factor at the start (the scale of u)."""

    model: object
    free: np.ndarray
    ext: np.ndarray
    f: np.ndarray
    c: float

    def residual(self, y, lam):
        return (self.model.forces(y) + lam * self.ext).ravel()[self.free]

    def factor(self, y):
        return _lu(self.model, self.free, y)

    def moved(self, y, du):
        z = y.copy().ravel()
        z[self.free] += du
        return z.reshape(-1, 3)

    @classmethod
    def at(cls, model, free, ext, x):
        """(the path from the equilibrium x, b = K(x)^-1 f): c is |b|."""
        f = ext.ravel()[free]
        b = _lu(model, free, x).solve(f)
        return cls(model, free, ext, f, max(np.linalg.norm(b), 1e-300)), b

    def tangent(self, b, prev=None):
        """The unit tangent (u / c, lambda) of K du = f dlambda (b = K^-1 f), oriented
        along ``prev``."""
        t = np.append(b / self.c, 1.0)
        t /= np.linalg.norm(t)
        return -t if prev is not None and t @ prev < 0 else t


def _corrected(p: _Path, x, lam, t, ds, tol, max_iter):
    """(y, l, the LU of the last iterate, iterations) of Newton on the equilibrium plus the
    arclength condition t . (z - z_prev) = ds from the predictor; None when it fails."""
    y, l, lu = p.moved(x, ds * p.c * t[:-1]), lam + ds * t[-1], None
    for it in range(max_iter):
        r = p.residual(y, l)
        g = t[:-1] @ ((y - x).ravel()[p.free] / p.c) + t[-1] * (l - lam) - ds
        if np.linalg.norm(r, np.inf) <= tol and abs(g) <= 1e-10 and it > 0:
            return y, l, lu, it
        try:
            lu = p.factor(y)
        except RuntimeError:
            return None
        a, bb = lu.solve(r), lu.solve(p.f)
        dl = (-g - t[:-1] @ a / p.c) / (t[:-1] @ bb / p.c + t[-1])
        du = a + bb * dl
        if not np.all(np.isfinite(du)):
            return None
        y, l = p.moved(y, du), l + dl
    return None


def arclength(
    model,
    graph,
    x,
    lam,
    free,
    ext,
    tol,
    *,
    max_iter: int = 12,
    steps: int = 150,
    ds: float = 0.02,
    ds_min: float = 1e-7,
    ds_max: float = 0.2,
) -> dict:
    """Pseudo-arclength continuation of f_int(x) + lambda f_ext = 0 from the equilibrium
    (x, lam) towards lambda = 1, in the scaled coordinates (u / c, lambda) with c the
    displacement per unit load factor at the start. Each step: predictor along the unit
    tangent t (from K du = f_ext dlambda, oriented along the previous one), Newton
    corrector on the equilibrium plus t . (z - z_prev) = ds (bordered solve with the
    sparse LU of K; the step halved until it converges); a sign change of the tangent's
    lambda component marks a limit point.
    Returns dict(x at lambda = 1 or None, lam, lam_max, folds, why, x_limit: the equilibrium
    next to the first limit point)."""
    p, b = _Path.at(model, free, ext, x)
    f = p.f
    t = p.tangent(b)
    folds, lam_max, why, x_limit = [], lam, "step size below the minimum", None
    for _ in range(steps):
        step = None
        while step is None and ds >= ds_min:
            step = _corrected(p, x, lam, t, ds, tol, max_iter)
            ds = ds if step is not None else ds / 2
        if step is None:
            return dict(x=None, lam=lam, lam_max=lam_max, folds=folds, why=why, x_limit=x_limit)
        y, l, lu, it = step
        tn = p.tangent(lu.solve(f), t)  # K of the last iterate: the tangent to O(|du|)
        if tn[-1] * t[-1] < 0:  # the fold lies between the two points
            folds.append(float(max(l, lam) if t[-1] > 0 else min(l, lam)))
            if x_limit is None:
                x_limit = y if (l > lam) == (t[-1] > 0) else x
        if l >= 1.0:  # passed the full load: settle on it with load control
            xs, done, _ = _newton(model, graph, y if l - 1.0 < 1.0 - lam else x, free, ext, tol, 30)
            if done:
                return dict(x=xs, lam=1.0, lam_max=1.0, folds=folds, why="", x_limit=x_limit)
            why = "Newton at the full load failed after the path crossed it"
            return dict(
                x=None, lam=l, lam_max=max(lam_max, l), folds=folds, why=why, x_limit=x_limit
            )
        x, lam, t = y, l, tn
        lam_max = max(lam_max, lam)
        if it <= 4:
            ds = min(1.5 * ds, ds_max)
    return dict(
        x=None, lam=lam, lam_max=lam_max, folds=folds, why=f"{steps} steps used", x_limit=x_limit
    )


def _newton(model, graph, x, free, ext, tol, max_iter):
    def residual(y):
        return (model.forces(y) + ext).ravel()[free]

    r = residual(x)
    for _ in range(max_iter):
        if np.linalg.norm(r, np.inf) <= tol:
            return x, True, 0.0
        K = stiffness(model, x)[free][:, free]
        dx = _solve_regularised(K, r)
        if dx is None:
            raise SimulationError(
                "singular stiffness", fix="fix more nodes: the body can move freely"
            )
        step, r0 = 1.0, np.linalg.norm(r)
        while True:
            y = x.copy().ravel()
            y[free] += step * dx
            y = y.reshape(-1, 3)
            ry = residual(y)
            if np.linalg.norm(ry) < r0 or step < 1e-4:
                break
            step *= 0.5
        x, r = y, ry
    ok = np.linalg.norm(r, np.inf) <= tol
    return x, ok, float(np.linalg.norm(r, np.inf))
