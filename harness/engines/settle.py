"""Static equilibrium by an engine's own dynamics, with a stated stopping rule.

An adapter wraps its engine in a :class:`Sim` (``load(ld)`` builds it at rest for one
pack load, ``set_damping``, ``advance(n)`` steps, ``measure()`` -> (u, v, f) with f the net
force on every node at the current state: external plus internal, held components
excluded) and calls :func:`settle`. Between steps the velocities are
scaled by exp(-c dt) (mass-proportional damping c = 2 omega_1), with omega_1 a function of
the load alone, so a load stops at the same place whatever other loads run beside it. For
the engines' tetrahedra it is the P1 model's lowest mode under the load's own holds
(:func:`lowest_omegas`), a lower bound on every mode the load excites: each then decays at
least at the rate omega_1, as the stationarity estimate assumes.

Stopping rule, every ``check`` steps (``measure`` averages u, v and f over them: a float32
engine's rounding keeps its high modes trembling). Settled when all hold:

- *stationary*: the displacement's change over the last K checks, divided by the share
  1 - exp(-omega_1 K check dt) >= 1/2 of the remaining error that damping at rate
  omega_1 removes in them (K the fewest checks that remove half: so it estimates the
  distance still to go), is at most ``rtol`` of the displacement's largest value, or at
  most 4 ``resolution`` (a float32 engine's positions ~0.5 m from the origin are
  multiples of 6e-8 m);
- *the residual is below its bound*, in every branch: the residual is the net force's
  work on the FEM's displacement relative to the external force's, |f . u_fem| / (f_ext .
  u_fem) (u = 0 gives 1; a body short by a share s of its load's shape gives about s),
  bounded by ``res_tol`` (:func:`residual_bound`);
- *the body moved along its load*: f_ext . u > 0 (an elastic body's u . K u), beyond what
  one float32 spacing per component could give: an adapter that drops the load and
  reports no net force is not at rest under it;
- *the net force is small or still*: |f| on the free components is at most ``force_tol``
  of |f_ext|, or it has stopped falling (by under 5 % over ``STALL`` checks) with the
  kinetic energy at most ``ke_tol`` of the load's work W = f . u_fem / 2. A float32
  engine's net force is a difference of O(E) terms at rounded positions: it stays
  0.1-0.8 of the load at nu = 0.49 on a converged body, but that rounding is rough
  (node to node) and does next to no work on the smooth u_fem, which the residual
  measures.

Diverged when a value is not finite or the displacement passes 1e3 times the FEM's; not
settled when the steps run out (the note gives the residual and its bound). The answer
reports steps, simulated and wall time, kinetic energy, the residual and the net force.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from harness.errors import SpringbenchError
from harness.registry import EXPORT_ENGINES, MATERIAL_ENGINES


class LoadLike(Protocol):
    """What a Sim reads of a pack load (harness/export/pack.py ``PackLoad``)."""

    held_nodes: np.ndarray  # (h,) node ids
    held_components: np.ndarray  # (h, dim) bool: which components are held
    force: np.ndarray  # (n, dim) N


class Sim(Protocol):
    """An engine wrapped for :func:`settle`: one model per load, stepped and measured."""

    def load(self, ld: LoadLike) -> None:
        """A fresh model at rest under ``ld``'s holds and forces."""

    def set_damping(self, factor: float) -> None:
        """Velocities are multiplied by ``factor`` after every step."""

    def advance(self, n: int) -> None:
        """``n`` steps (an average over them for :meth:`measure`)."""

    def measure(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u, v, f) at the current state (f: the net force, held components excluded)."""


RTOL = 1e-4  # the displacement's change between checks, relative to its largest value
# The residual's bound: a body 0.1 % of its load's work short of equilibrium fails it, u = 0
# (1.0) by 1000x; converged runs stop below it: Newton (float32) at 2e-7..6e-4 on the
# engine suite's fine bodies at nu = 0.49 (taper tip the largest), MuJoCo at <= 5e-5.
RES_TOL = 1e-3
FORCE_TOL = 1e-2  # the net force, relative to the external force, when not stalled
KE_TOL = 1e-3  # kinetic energy, relative to the load's work, with a stalled net force
STALL = 10  # checks over which a net force that fell by under 5 % has stalled
CHECK = 200  # steps between checks
MAX_STEPS = 400_000


@dataclass(frozen=True)
class Answer:
    """One load's equilibrium: ``u`` (n, dim) (NaN when it has none), ``status``
    ("settled", "not-settled", "diverged", "unsupported", "unsupported-load"), the steps
    and simulated time it took, its wall time, the final kinetic energy (J), the residual
    (module docstring) and the net force relative to the external force."""

    u: np.ndarray
    status: str
    steps: int = 0
    sim_time: float = 0.0
    wall: float = 0.0
    kinetic: float = math.nan
    residual: float = math.nan
    note: str = ""
    force_residual: float = math.nan


def float32_resolution(points: np.ndarray) -> float:
    """The spacing of float32 numbers at the body's largest coordinate (m)."""
    return float(np.spacing(np.float32(np.abs(points).max())))


UNSUPPORTED = ("unsupported", "unsupported-load")  # the body, or this load alone


def unsupported(pack, why: str, status: str = "unsupported") -> Answer:
    """No displacement: the engine cannot run the pack's body ("unsupported") or this load
    of it ("unsupported-load", e.g. nodal forces an engine takes no input for)."""
    return Answer(np.full((pack.n_nodes, pack.dim), np.nan), status, note=why)


def no_model(options, engine: str) -> None:
    """One line when ``options`` names a model: ``engine`` runs the pack's own material."""
    if (options or {}).get("model") is None:
        return
    raise SpringbenchError(
        f"{engine} runs the pack's own material (E, nu) and takes no model",
        file=str(options["model"]),
        field="--model",
        fix=f"drop --model, or use {', '.join(EXPORT_ENGINES + MATERIAL_ENGINES)}",
    )


def tetrahedra(pack) -> np.ndarray | None:
    """The pack's tetrahedra (m, 4), or None when its body is not a 3-D tetrahedral mesh."""
    tets = pack.cells.get("tetra")
    if pack.dim != 3 or tets is None or not len(tets):
        return None
    return np.asarray(tets, int)


def not_tetrahedra(pack, engine: str) -> dict:
    """Every load ``unsupported``: ``engine`` runs 3-D tetrahedral meshes only."""
    return {
        ld.name: unsupported(pack, f"{engine} needs a 3-D tetrahedral mesh") for ld in pack.loads
    }


GRAVITY_RTOL = 1e-6  # a body-force load's forces are the lumped masses times its gravity


def gravity_of(ld, masses: np.ndarray) -> np.ndarray | None:
    """The load's gravity (3,) m/s^2 when its forces are the lumped masses times it, else
    None (a traction or a point force: an engine without nodal forces cannot apply it)."""
    if ld.gravity is None:
        return None
    g = np.asarray(ld.gravity, float)
    body = masses[:, None] * g[None, :]
    scale = max(float(np.abs(body).max()), 1e-300)
    return g if float(np.abs(ld.force - body).max()) <= GRAVITY_RTOL * scale else None


def gravity_only(ld, masses: np.ndarray, engine: str, holds: str) -> str | None:
    """Why ``engine`` (no nodal forces; it ``holds`` whole nodes) cannot run the load, or
    None: a gravity load on whole held nodes."""
    if gravity_of(ld, masses) is None:
        return f"{engine} takes no nodal forces: gravity loads only"
    if not ld.held_components.all(axis=1).all():
        return f"{engine} {holds} whole nodes: no partly held nodes"
    return None


def rayleigh_omega(load, masses: np.ndarray) -> float:
    """omega (rad/s) of the load's static shape: omega^2 = f . u / (u . M u), close above
    the lowest mode the load excites (the FEM's u_fem and the pack's forces)."""
    u, f = load.u_fem, load.force
    den = float(np.sum(masses[:, None] * u * u))
    num = float(np.sum(f * u))
    return math.sqrt(num / den) if den > 0 and num > 0 else math.nan


def p1_scaled_stiffness(points: np.ndarray, tets: np.ndarray, E, nu, masses):
    """M^-1/2 K M^-1/2 (csr, node-major dofs) of the P1 (linear tetrahedra) model with
    lumped masses: its eigenvalues are the squared angular frequencies of the free body.
    ``E``, ``nu``: one material, or one per tetrahedron (arrays (m,))."""
    import scipy.sparse as sp
    import skfem
    from skfem.helpers import ddot, div, sym_grad
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = skfem.MeshTet(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    if np.ndim(E) == 0 and np.ndim(nu) == 0:
        K = skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis).tocsr()
    else:  # a Lame pair per element: P0 fields

        @skfem.BilinearForm
        def form(u, v, w):
            return 2.0 * w.mu * ddot(sym_grad(u), sym_grad(v)) + w.lam * div(u) * div(v)

        lam, mu = lame_parameters(*np.broadcast_arrays(np.asarray(E, float), nu))
        p0 = basis.with_element(skfem.ElementTetP0())
        K = skfem.asm(form, basis, lam=p0.interpolate(lam), mu=p0.interpolate(mu)).tocsr()
    s = sp.diags(1.0 / np.sqrt(np.repeat(masses, 3)))  # skfem's interleaved dofs: node-major
    return (s @ K @ s).tocsr()


def omega_max(A) -> float:
    """The largest omega (rad/s) of the scaled stiffness ``A``: a continuum engine's explicit
    step limit is about 2 / omega_max (a fixed start vector: the same answer every run)."""
    import scipy.sparse.linalg as spla

    v0 = np.random.default_rng(0).standard_normal(A.shape[0])
    lam = spla.eigsh(A, k=1, which="LA", tol=1e-6, v0=v0)[0]
    return float(np.sqrt(max(lam[0], 0.0)))


def free_mask(load) -> np.ndarray:
    """(n, dim) True where the load leaves a component free."""
    free = np.ones(load.force.shape, bool)
    free[load.held_nodes] = ~load.held_components
    return free


def lowest_omegas(A, loads) -> dict:
    """{load name: the lowest omega (rad/s) of the scaled stiffness ``A`` with that load's
    held components removed}: a lower bound on every mode the load excites, a function of
    the load's own holds only (loads sharing holds share one eigen-solve)."""
    import scipy.sparse.linalg as spla

    out, seen = {}, {}
    for ld in loads:
        free = np.flatnonzero(free_mask(ld).ravel())
        key = free.tobytes()
        if key not in seen:
            B = A[free][:, free].tocsc()
            v0 = np.random.default_rng(0).standard_normal(len(free))
            lam = spla.eigsh(B, k=1, sigma=0.0, which="LM", tol=1e-8, v0=v0)[0]
            seen[key] = math.sqrt(lam[0]) if lam[0] > 0 else math.nan
        out[ld.name] = seen[key]
    return out


def residual_bound(load, free: np.ndarray, resolution: float, res_tol: float = RES_TOL) -> float:
    """``res_tol``, or the residual a rounding of one float32 spacing per component could
    leave (its work |f| . resolution on the load's work f . u_fem), when that is larger."""
    fw = float(np.sum(load.force[free] * load.u_fem[free]))
    rounding = resolution * float(np.abs(load.force[free]).sum()) / fw if fw > 0 else 0.0
    return max(res_tol, rounding)


def residuals(f: np.ndarray, free: np.ndarray, load) -> tuple[float, float]:
    """(residual, net force) of the module docstring: the net force's work on u_fem over
    the external force's, and |f| over |f_ext| on the free components."""
    fext = float(np.linalg.norm(load.force[free]))
    force = float(np.linalg.norm(f[free]))
    force = force / fext if fext > 0 else force
    fw = float(np.sum(load.force[free] * load.u_fem[free]))
    res = abs(float(np.sum(f[free] * load.u_fem[free]))) / fw if fw > 0 else force
    return res, force


def _moved(u: np.ndarray, load, free: np.ndarray, resolution: float) -> bool:
    """Whether the load's work on u is positive, beyond one float32 spacing per component."""
    f = load.force[free]
    return float(np.sum(f * u[free])) > resolution * float(np.abs(f).sum())


def _span(omega1: float, check: int, dt: float) -> tuple[float, int, float]:
    """(damping c, checks K, share removed in K checks) for the stationarity estimate."""
    c = 2.0 * omega1 if math.isfinite(omega1) else 0.0
    span = max(1, math.ceil(math.log(2.0) / (0.5 * c * check * dt))) if c > 0 else 1
    removed = -math.expm1(-0.5 * c * span * check * dt) if c > 0 else 1.0
    return c, span, removed


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
    force_tol: float = FORCE_TOL,
) -> Answer:
    """Run ``sim`` to equilibrium under ``load`` (module docstring)."""
    t0 = time.perf_counter()
    free = free_mask(load)
    umax = float(np.linalg.norm(load.u_fem, axis=1).max())
    work = 0.5 * float(np.sum(load.force * load.u_fem))
    bound = residual_bound(load, free, resolution, res_tol)
    c, span, removed = _span(omega1, check, dt)
    sim.set_damping(math.exp(-c * dt))
    past, steps, history = [], 0, []
    while steps < max_steps:
        sim.advance(check)
        steps += check
        u, v, f = sim.measure()
        ke = 0.5 * float(np.sum(masses[:, None] * v * v))
        res, force = residuals(f, free, load)
        run = (steps, steps * dt, time.perf_counter() - t0, ke, res)
        if not (np.all(np.isfinite(u)) and math.isfinite(res)) or np.abs(u).max() > 1e3 * max(
            umax, 1e-300
        ):
            note = f"at step {steps} (dt {dt:.3g} s)"
            return Answer(np.full_like(u, np.nan), "diverged", *run, note, force)
        past.append(u)
        before = past.pop(0) if len(past) > span else None
        scale = max(float(np.abs(u).max()), 4.0 * resolution / rtol, 1e-300)
        change = math.inf if before is None else float(np.abs(u - before).max()) / removed / scale
        history.append(force)
        stalled = len(history) > STALL and force >= 0.95 * history[-1 - STALL]
        still = force <= force_tol or (stalled and ke <= ke_tol * work)
        if change <= rtol and res <= bound and still and _moved(u, load, free, resolution):
            note = "" if force <= force_tol else f"net force {force:.2g} of the load, stalled"
            return Answer(u, "settled", *run, note, force)
    note = f"residual {res:.2g} (bound {bound:.2g}), net force {force:.2g}, after {steps} steps"
    return Answer(u, "not-settled", *run, note, force)
