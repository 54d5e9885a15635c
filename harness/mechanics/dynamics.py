"""Time integration of the nonlinear particle models (mass-spring, the
Bourguignon-Cani elements), shared by every model with ``forces(x, v)``,
``node_graph()`` and ``n_nodes``.

- ``verlet``: position (Stoermer) Verlet as the original program, d_{n+1} = d_n + h^2 a_n,
  x_{n+1} = x_n + d_{n+1}, damping on v = d/h (the program's per-step constants are
  kd*h physically). For MassSpring / AnisotropicBody a compiled kernel (numba,
  harness/models/bc2000/kernels.py, vectorised over blocks of elements) runs the whole
  loop; it reproduces the program's particle states to rounding (tests/test_bc2000.py).
- ``symplectic-euler``: v += h a(x, v); x += h v (numpy, any model).
- ``backward-euler``: one Newton step per step with the Jacobian of the forces (complex
  step, coloured, sparse): (M - h D - h^2 K) dv = h (f + h K v).
- ``stable_step``: 2 / omega_max of the linearised K and M (free dofs).
- statics (``solve_static``, ``solve_static_path``: Newton with load steps, arc-length
  continuation through limit points) live in harness/mechanics/static_path.py.

A run that blows up raises SimulationError naming the step and the stable-step estimate.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.errors import SimulationError
from harness.models.bc2000.pack import kernel_arrays

INTEGRATORS = ("verlet", "symplectic-euler", "backward-euler")
PROGRAM_DRAG = 5e-3  # the program's drag per step: -5e-3 d (physical 5e-3 h N s/m)


@dataclass(frozen=True)
class Loading:
    """What acts on the particles: mass (n,) kg, fixed (n,) bool, gravity (3,) m/s^2,
    push (n, 3) constant forces N, drag (physical N s/m, force -drag v)."""

    mass: np.ndarray
    fixed: np.ndarray
    gravity: np.ndarray
    push: np.ndarray
    drag: float = 0.0

    @staticmethod
    def from_flags(
        flags,
        *,
        mass=0.01,
        gravity=(0.0, -9.8, 0.0),
        push=(0.0, -1.0, 0.0),
        drag=0.0,
        observed_fixed: bool = False,
    ) -> "Loading":
        """From the program's node flags: 1 fixed, 2 pushed/pulled (force ``push``),
        3 observed (free unless ``observed_fixed``, as in the program's non-MEASURE build)."""
        flags = np.asarray(flags)
        n = len(flags)
        fixed = (flags == 1) | ((flags == 3) & observed_fixed)
        p = np.zeros((n, 3))
        p[flags == 2] = push
        return Loading(
            np.broadcast_to(np.asarray(mass, float), (n,)).copy(),
            fixed,
            np.asarray(gravity, float),
            p,
            float(drag),
        )

    def external(self) -> np.ndarray:
        return self.mass[:, None] * self.gravity[None, :] + self.push


@dataclass(frozen=True)
class Trajectory:
    """t (k,), volume (k,) (sum of unsigned tet volumes, nan if the model has no cells),
    observed (k, n_obs, 3) positions of the observed nodes, snapshots {step: (x, d)} with
    d = x_n - x_{n-1}; x, v at the end; energy (k,) (kinetic + gravity + model potential)
    if asked."""

    t: np.ndarray
    volume: np.ndarray
    observed: np.ndarray
    snapshots: dict
    x: np.ndarray
    v: np.ndarray
    dt: float
    energy: np.ndarray | None = None

    def volume_change_percent(self) -> np.ndarray:
        return 100.0 * (self.volume - self.volume[0]) / self.volume[0]


def tet_volume(x, tets) -> float | np.ndarray:
    """Sum of unsigned tetrahedron volumes; x (n, 3) or (k, n, 3)."""
    X = x[..., tets, :]
    a, b, c = X[..., 1, :] - X[..., 0, :], X[..., 2, :] - X[..., 0, :], X[..., 3, :] - X[..., 0, :]
    det = np.sum(np.cross(a, b) * c, axis=-1)
    return np.abs(det).sum(axis=-1) / 6.0


# -- compiled position Verlet (the program's loop) ---------------------------------------------


def _kernel():
    """The compiled position-Verlet loop of the program (harness/models/bc2000/kernels.py;
    its arithmetic is rearranged, so it matches the program to rounding, not bit for bit)."""
    from harness.models.bc2000.kernels import run

    return run


def _kernel_arrays(model, dt, threads=1):
    """Model arrays for the compiled loop (harness/models/bc2000/pack.py): (springs, tets,
    hexes) argument tuples, empty where the model has none; None for other models."""
    return kernel_arrays(model, dt, threads)


def _tets_of(model):
    t = model.tets() if hasattr(model, "tets") else None
    return np.zeros((0, 4), np.int64) if t is None else np.asarray(t, np.int64)


def _check(integrator: str, engine: str, dt: float, steps: int) -> None:
    """One line for an unknown integrator or engine, or a step that cannot run."""
    if integrator not in INTEGRATORS:
        raise SimulationError(
            f"unknown integrator '{integrator}'", fix=f"one of {', '.join(INTEGRATORS)}"
        )
    if engine not in ("auto", "numba", "numpy"):
        raise SimulationError(f"unknown engine '{engine}'", fix="one of auto, numba, numpy")
    if dt <= 0 or steps < 0:
        raise SimulationError(f"need dt > 0 and steps >= 0 (got dt={dt}, steps={steps})")


def _compiled(model, loading, arrays, x, dt, steps, tets, obs, snap_steps, out, size, threads):
    """The compiled verlet run (x moved in place; ``out``: the snapshot, snapshot-step,
    volume and observed arrays it fills): the final velocities."""
    snaps, snaps_d, vol, observed = out
    d = np.zeros((len(x), 3))
    springs, tet, hexa = arrays
    done = _kernel()(
        x,
        d,
        int(steps),
        float(dt),
        loading.mass.astype(float),
        ~loading.fixed,
        loading.mass[:, None] * loading.gravity[None, :],
        loading.push.astype(float),
        float(loading.drag / dt),
        springs,
        tet,
        hexa,
        tets,
        obs,
        snap_steps,
        snaps,
        snaps_d,
        vol,
        observed,
        10.0 * size,
        threads >= 2,
    )
    if done < steps:
        _blow_up(model, loading, dt, done)
    return d / dt


def simulate(
    model,
    loading: Loading,
    dt: float,
    steps: int,
    *,
    integrator: str = "verlet",
    snapshots=(),
    observe=(),
    x0=None,
    engine: str = "auto",
    energy: bool = False,
    jacobian_every: int = 1,
    volume: bool = True,
    threads: int = 1,
) -> Trajectory:
    """Run ``steps`` steps of size ``dt`` from rest (x0 default: the rest points).

    ``snapshots``: step numbers whose full state is kept; ``observe``: node ids whose
    positions are kept every step. ``engine``: "numba" (verlet only), "numpy" or "auto".
    ``volume``: measure the volume every step (off for timing runs). ``threads``: 2 runs
    the elements on two threads (same result bit for bit; pays off on free cores).
    """
    _check(integrator, engine, dt, steps)
    x = np.array(model.points if x0 is None else x0, float)
    n = len(x)
    snap_steps = np.array(sorted({int(s) for s in snapshots if 0 <= int(s) <= steps}), np.int64)
    obs = np.asarray(observe, np.int64).reshape(-1)
    tets = _tets_of(model) if volume else np.zeros((0, 4), np.int64)
    size = float((model.points.max(axis=0) - model.points.min(axis=0)).max()) or 1.0
    arrays = (
        _kernel_arrays(model, dt, threads)
        if integrator == "verlet" and engine in ("auto", "numba")
        else None
    )
    if engine == "numba" and arrays is None:
        raise SimulationError(
            "the compiled engine runs verlet on MassSpring or AnisotropicBody only"
        )
    vol = np.full(steps + 1, np.nan)
    observed = np.zeros((steps + 1, len(obs), 3))
    snaps = np.zeros((len(snap_steps), n, 3))
    snaps_d = np.zeros((len(snap_steps), n, 3))
    out = (snaps, snaps_d, vol, observed)
    if arrays is not None:
        v = _compiled(
            model, loading, arrays, x, dt, steps, tets, obs, snap_steps, out, size, threads
        )
    else:
        x, v = _numpy_run(
            model,
            loading,
            x,
            dt,
            steps,
            integrator,
            tets,
            obs,
            snap_steps,
            *out,
            size,
            jacobian_every,
        )
    if len(tets) == 0:
        vol[:] = np.nan
    t = dt * np.arange(steps + 1)
    en = None
    if energy and len(snap_steps):
        en = np.array(
            [_energy(model, loading, snaps[k], snaps_d[k] / dt) for k in range(len(snap_steps))]
        )
    kept = {int(s): (snaps[k], snaps_d[k]) for k, s in enumerate(snap_steps)}
    return Trajectory(t, vol, observed, kept, x, v, dt, en)


def _energy(model, loading, x, v):
    kin = 0.5 * np.sum(loading.mass[:, None] * v * v)
    pot = -np.sum(loading.external() * (x - model.points))
    return kin + pot + model.energy(x)


def _blow_up(model, loading, dt, step):
    try:
        est = f"{stable_step(model, loading):.3g} s"
    except Exception:  # the estimate is advice only
        est = "unknown"
    raise SimulationError(
        f"the simulation blew up at step {step} with dt = {dt:g} s "
        f"(stable-step estimate 2/omega_max = {est})",
        fix="reduce dt or use integrator = 'backward-euler'",
    )


def _numpy_run(
    model,
    loading,
    x,
    dt,
    steps,
    integrator,
    tets,
    obs,
    snap_steps,
    snaps,
    snaps_d,
    volume,
    observed,
    size,
    jacobian_every,
):
    n = len(x)
    free = ~loading.fixed
    minv = np.where(free, 1.0 / loading.mass, 0.0)[:, None]
    ext = loading.external()
    v = np.zeros((n, 3))
    d = np.zeros((n, 3))
    isnap = 0
    J = None
    for step in range(steps + 1):
        if len(tets):
            volume[step] = tet_volume(x, tets)
        if len(obs):
            observed[step] = x[obs]
        if isnap < len(snap_steps) and snap_steps[isnap] == step:
            snaps[isnap], snaps_d[isnap] = x, d
            isnap += 1
        if step == steps:
            break
        if integrator in ("verlet", "symplectic-euler"):
            f = model.forces(x, v) - loading.drag * v + ext
            v_new = v + dt * f * minv
        else:
            if J is None or step % jacobian_every == 0:
                J = _implicit_matrices(model, x, v, free)
            v_new = _backward_euler_step(model, loading, x, v, dt, free, ext, J)
        x_new = x + dt * v_new
        d = x_new - x
        x, v = x_new, v_new
        if not np.all(np.abs(d) < 10.0 * size):
            _blow_up(model, loading, dt, step + 1)
    return x, v


def _implicit_matrices(model, x, v, free):
    Kx = jacobian(model.forces, x, model.node_graph(), v=v, wrt="x")
    Kv = jacobian(model.forces, x, model.node_graph(), v=v, wrt="v")
    return Kx, Kv


def _backward_euler_step(model, loading, x, v, dt, free, ext, J):
    Kx, Kv = J
    dof = np.repeat(free, 3)
    M = sp.diags(np.repeat(loading.mass, 3))
    A = (M - dt * (Kv - loading.drag * sp.eye(Kv.shape[0])) - dt * dt * Kx).tocsr()[dof][:, dof]
    f = model.forces(x, v) - loading.drag * v + ext
    b = dt * (f.ravel() + dt * (Kx @ v.ravel()))[dof]
    dv = np.zeros(3 * len(x))
    dv[dof] = spla.spsolve(A.tocsc(), b)
    return v + dv.reshape(-1, 3)


# -- Jacobians ----------------------------------------------------------------------------------


def distance2_colouring(graph: sp.spmatrix) -> np.ndarray:
    """Greedy colouring in which nodes within two edges of each other differ (columns of
    one colour can be perturbed together without their rows overlapping)."""
    A = (sp.csr_matrix(graph, dtype=float) + sp.eye(graph.shape[0])).tocsr()
    A2 = (A @ A).tocsr()
    colour = np.full(A.shape[0], -1)
    for i in range(A.shape[0]):
        used = set(colour[A2.indices[A2.indptr[i] : A2.indptr[i + 1]]].tolist())
        c = 0
        while c in used:
            c += 1
        colour[i] = c
    return colour


def jacobian(force, x, graph, *, v=None, wrt: str = "x", h: float = 1e-30) -> sp.csr_matrix:
    """d force / d x (or d v), (3n, 3n) sparse, exact to rounding by the complex step:
    one complex force evaluation per colour and component."""
    x = np.asarray(x, float)
    n = len(x)
    A = (sp.csr_matrix(graph, dtype=float) + sp.eye(n)).tocoo()
    colour = distance2_colouring(graph)
    rows, cols, vals = [], [], []
    for c in range(colour.max() + 1):
        nodes = np.flatnonzero(colour == c)
        sel = np.isin(A.col, nodes)
        r, j = A.row[sel], A.col[sel]
        for comp in range(3):
            if wrt == "x":
                xp = x.astype(complex)
                xp[nodes, comp] += 1j * h
                f = force(xp, v)
            else:
                vp = (np.zeros_like(x) if v is None else np.asarray(v, float)).astype(complex)
                vp[nodes, comp] += 1j * h
                f = force(x, vp)
            im = np.imag(f) / h
            for k in range(3):
                rows.append(3 * r + k), cols.append(3 * j + comp), vals.append(im[r, k])
    N = 3 * n
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(N, N)
    )


def stiffness(model, x=None) -> sp.csr_matrix:
    """K = -d f / d x at x (default rest): the model's own ``tangent_stiffness`` (element by
    element) or ``stiffness_matrix`` (analytic) where it has one, else the coloured complex
    step of :func:`jacobian` (all three agree to rounding; tests)."""
    x = model.points if x is None else x
    for name in ("tangent_stiffness", "stiffness_matrix"):
        if hasattr(model, name):
            return getattr(model, name)(x).tocsr()
    return -jacobian(model.forces, x, model.node_graph())


def stable_step(model, loading: Loading, x=None) -> float:
    """2 / omega_max, omega_max^2 the largest eigenvalue of M^-1/2 K_sym M^-1/2 on the
    free dofs: the explicit (Verlet / symplectic Euler) stability limit without damping."""
    K = stiffness(model, x)
    K = 0.5 * (K + K.T)
    dof = np.repeat(~loading.fixed, 3)
    s = 1.0 / np.sqrt(np.repeat(loading.mass, 3))[dof]
    Kf = sp.diags(s) @ K.tocsr()[dof][:, dof] @ sp.diags(s)
    if Kf.shape[0] <= 200:
        lam = np.linalg.eigvalsh(Kf.toarray()).max()
    else:
        lam = spla.eigsh(
            Kf,
            k=1,
            which="LA",
            return_eigenvectors=False,
            tol=1e-6,
            v0=np.random.default_rng(0).standard_normal(Kf.shape[0]),
        )[0]  # seeded start
    return float("inf") if lam <= 0 else 2.0 / np.sqrt(lam)


def _solve_regularised(K, r):
    """K dx = r; a stiffness with zero modes (a straight chain has no transverse
    stiffness) is shifted by 1e-10 of its diagonal scale. None if still singular."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", spla.MatrixRankWarning)
        try:
            dx = spla.spsolve(K.tocsc(), r)
        except RuntimeError:
            dx = np.full(len(r), np.nan)
        if not np.all(np.isfinite(dx)):
            shift = 1e-10 * max(np.abs(K.diagonal()).max(), 1e-300)
            try:
                dx = spla.spsolve((K + shift * sp.eye(K.shape[0])).tocsc(), r)
            except RuntimeError:
                return None
    return dx if np.all(np.isfinite(dx)) else None
