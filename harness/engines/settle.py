"""Static equilibrium by an engine's own dynamics, with a stated stopping rule.

An adapter wraps its engine in a ``Sim`` (``advance(n)`` steps, ``measure()`` -> (u, v,
f) with f the net force on every node at the current state: external plus internal,
held components excluded) and calls :func:`settle`. Between steps the velocities are
scaled by exp(-c dt) (mass-proportional damping c = 2 omega_1, about critical for the
body's lowest mode, :func:`pack_omega`), so equilibrium comes in tens of periods of
that mode, not in millions of steps.

Stopping rule, every ``check`` steps (``measure`` averages u, v and f over them: a float32
engine's rounding keeps its high modes trembling):

- *stationary*: the displacement's change over the last K checks, divided by the share
  1 - exp(-omega_1 K check dt) >= 1/2 of the remaining error that damping at rate
  omega_1 removes in them (K the fewest checks that remove half: so it estimates the
  distance still to go, and float32 noise in a small change is not magnified), is at most
  ``rtol`` of the displacement's largest value, or at most 4 ``resolution`` (a float32
  engine's positions ~0.5 m from the origin are multiples of 6e-8 m);
- *in equilibrium*: the net force |f| on the free components is at most ``res_tol`` of the
  external force, or it has stopped falling (by under 5 % over ``STALL`` checks) while the
  kinetic energy of the averaged motion (the slow modes, which move the averaged
  displacement) is at most ``ke_tol`` of the load's work W = f . u_fem / 2. The second
  is float32 rounding: forces are differences of O(E) terms and the high modes are
  stiff, so on a steel lug (632 nodes, omega_max / omega_1 ~ 1e3) the averaged force stays
  5-10 % of the load while the averaged position is Newton's P1 answer to 2e-3;
  the trembling is fast and small in displacement.

Settled when both hold; diverged when a value is not finite or the displacement passes
1e3 times the FEM's; not settled when the steps run out. The answer reports steps,
simulated and wall time, kinetic energy and the relative residual.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

RTOL = 1e-4  # the displacement's change between checks, relative to its largest value
RES_TOL = 1e-2  # the residual force, relative to the external force
KE_TOL = 1e-3  # kinetic energy, relative to the load's work, with a stalled residual
STALL = 10  # checks over which a residual that fell by under 5 % has stalled
CHECK = 200  # steps between checks
MAX_STEPS = 400_000


@dataclass(frozen=True)
class Answer:
    """One load's equilibrium: ``u`` (n, dim) (NaN when it has none), ``status``
    ("settled", "not-settled", "diverged", "unsupported"), the steps and simulated time
    it took, its wall time, the final kinetic energy (J) and relative residual force."""

    u: np.ndarray
    status: str
    steps: int = 0
    sim_time: float = 0.0
    wall: float = 0.0
    kinetic: float = math.nan
    residual: float = math.nan
    note: str = ""


def float32_resolution(points: np.ndarray) -> float:
    """The spacing of float32 numbers at the body's largest coordinate (m)."""
    return float(np.spacing(np.float32(np.abs(points).max())))


def unsupported(pack, why: str) -> Answer:
    return Answer(np.full((pack.n_nodes, pack.dim), np.nan), "unsupported", note=why)


def rayleigh_omega(load, masses: np.ndarray) -> float:
    """omega (rad/s) of the load's static shape: omega^2 = f . u / (u . M u), close above
    the lowest mode the load excites (the FEM's u_fem and the pack's forces)."""
    u, f = load.u_fem, load.force
    den = float(np.sum(masses[:, None] * u * u))
    num = float(np.sum(f * u))
    return math.sqrt(num / den) if den > 0 and num > 0 else math.nan


def pack_omega(pack, masses: np.ndarray) -> float:
    """The smallest :func:`rayleigh_omega` over the pack's loads: about the body's lowest
    mode under its softest clamp (a cantilever's first bending mode). Damping every load
    with c = 2 omega of it decays every mode at a rate of about omega; a load's own, higher
    quotient (a stress state's) would overdamp the soft modes, which then creep for
    100,000s of steps."""
    omegas = [rayleigh_omega(ld, masses) for ld in pack.loads]
    finite = [w for w in omegas if math.isfinite(w)]
    return min(finite) if finite else math.nan


def p1_omega_max(
    points: np.ndarray, tets: np.ndarray, E: float, nu: float, masses: np.ndarray
) -> float:
    """The largest omega (rad/s) of the free P1 (linear tetrahedra) model with lumped
    masses: a continuum engine's explicit step limit is about 2 / omega_max."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = skfem.MeshTet(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    K = skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis).tocsr()
    s = sp.diags(1.0 / np.sqrt(np.repeat(masses, 3)))  # skfem's interleaved dofs: node-major
    A = (s @ K @ s).tocsr()
    lam = spla.eigsh(
        A, k=1, which="LA", tol=1e-6, v0=np.random.default_rng(0).standard_normal(A.shape[0])
    )[0]
    return float(np.sqrt(max(lam[0], 0.0)))


def settle(
    sim,
    load,
    masses: np.ndarray,
    dt: float,
    omega1: float,
    max_steps: int = MAX_STEPS,
    rtol: float = RTOL,
    check: int = CHECK,
    res_tol: float = RES_TOL,
    ke_tol: float = KE_TOL,
    resolution: float = 0.0,
) -> Answer:
    """Run ``sim`` to equilibrium under ``load`` (module docstring)."""
    t0 = time.perf_counter()
    free = np.ones(load.force.shape, bool)
    free[load.held_nodes] = ~load.held_components
    fext = float(np.linalg.norm(load.force[free]))
    umax = float(np.linalg.norm(load.u_fem, axis=1).max())
    work = 0.5 * float(np.sum(load.force * load.u_fem))
    c = 2.0 * omega1 if math.isfinite(omega1) else 0.0
    span = max(1, math.ceil(math.log(2.0) / (0.5 * c * check * dt))) if c > 0 else 1
    removed = -math.expm1(-0.5 * c * span * check * dt) if c > 0 else 1.0
    sim.set_damping(math.exp(-c * dt))
    past, steps, history = [], 0, []
    while steps < max_steps:
        sim.advance(check)
        steps += check
        u, v, f = sim.measure()
        ke = 0.5 * float(np.sum(masses[:, None] * v * v))
        res = float(np.linalg.norm(f[free])) / fext if fext > 0 else float(np.linalg.norm(f[free]))
        if not (np.all(np.isfinite(u)) and math.isfinite(res)) or np.abs(u).max() > 1e3 * max(
            umax, 1e-300
        ):
            return Answer(
                np.full_like(u, np.nan),
                "diverged",
                steps,
                steps * dt,
                time.perf_counter() - t0,
                ke,
                res,
                f"at step {steps} (dt {dt:.3g} s)",
            )
        past.append(u)
        before = past.pop(0) if len(past) > span else None
        scale = max(float(np.abs(u).max()), 4.0 * resolution / rtol, 1e-300)
        change = math.inf if before is None else float(np.abs(u - before).max()) / removed / scale
        history.append(res)
        stalled = len(history) > STALL and res >= 0.95 * history[-1 - STALL]
        if change <= rtol and (res <= res_tol or (stalled and ke <= ke_tol * work)):
            note = (
                ""
                if res <= res_tol
                else f"residual {res:.2g} stalled, kinetic {ke / work:.1g} of the work"
            )
            return Answer(u, "settled", steps, steps * dt, time.perf_counter() - t0, ke, res, note)
    return Answer(
        u,
        "not-settled",
        steps,
        steps * dt,
        time.perf_counter() - t0,
        ke,
        res,
        f"residual {res:.2g} after {steps} steps",
    )
