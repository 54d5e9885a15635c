"""Self-contained spring networks for optimiser tests and benchmarks.

A regular grid with diagonals, loaded like the basic load sets (docs/design.md, "Load
sets for boxes": stretch with rollers on the opposite face, shear with that face
clamped), and a *recoverable* reference: the displacements of the same network with
known, randomly perturbed constants, so the best G is exactly 0. Independent of
harness/models on purpose.
"""

from __future__ import annotations

import itertools

import numpy as np

from harness.models.springs import incidence, stiffness_matrix
from harness.optimize.problem import FitProblem

AXES = "xyz"


def grid_network(shape, spacing=1.0, diagonals: str = "all"):
    """Nodes on a regular grid (shape = nodes per axis) and springs.

    2-D: edges + both cell diagonals (Deussen's structure 1). 3-D: edges + both face
    diagonals of every face; ``diagonals="all"`` adds the four body diagonals.
    Returns points (n, dim), springs (e, 2) int and a group id per spring
    (0 = edge along x, 1 = along y, [2 = along z], then one id per diagonal class).
    """
    shape = tuple(int(s) for s in shape)
    dim = len(shape)
    idx = np.arange(np.prod(shape)).reshape(shape, order="F")  # node = i + nx*j (+ nx*ny*l)
    grids = np.meshgrid(*[np.arange(s) * spacing for s in shape], indexing="ij")
    points = np.stack([g.ravel(order="F") for g in grids], axis=1).astype(float)
    offsets = []
    for o in itertools.product((-1, 0, 1), repeat=dim):
        o = np.array(o)
        nz = np.count_nonzero(o)
        if nz == 0 or o[np.nonzero(o)[0][0]] < 0:  # keep one of each +-pair
            continue
        if nz == 3 and diagonals != "all":
            continue
        offsets.append(o)
    offsets.sort(key=lambda o: (np.count_nonzero(o), tuple(-abs(o))))
    springs, groups = [], []
    for g, o in enumerate(offsets):
        src = tuple(slice(max(0, -d), sz - max(0, d)) for d, sz in zip(o, shape))
        dst = tuple(slice(sl.start + d, sl.stop + d) for sl, d in zip(src, o))
        a, b = idx[src].ravel(), idx[dst].ravel()
        springs.append(np.stack([a, b], axis=1))
        groups.append(np.full(len(a), g))
    return points, np.concatenate(springs), np.concatenate(groups)


def basic_loads(points: np.ndarray, s: float = 1.0):
    """Load cases like basic2d/basic3d (docs/design.md, "Load sets for boxes") on the grid's
    bounding box.

    Returns names, free_masks (L, ndof) bool, forces (L, ndof). Stretch-a: nodal force
    along +a on face a = a1, rollers (u_a = 0) on face a = a0, rigid motion removed at the
    min corner (and one more corner in 3-D). Shear-ab: face b = b0 clamped, force along +a
    on face b = b1. Forces are equal per face node, halved/quartered at face borders.
    """
    n, dim = points.shape
    lo, hi = points.min(0), points.max(0)
    tol = 1e-9 * max(1.0, float(np.max(hi - lo)))
    at_lo = np.abs(points - lo) < tol
    at_hi = np.abs(points - hi) < tol
    names, frees, forces = [], [], []

    def face_force(axis):
        on = at_hi[:, axis]
        wgt = np.ones(n)
        for other in range(dim):
            if other != axis:
                wgt[(at_lo[:, other] | at_hi[:, other])] *= 0.5
        wgt = np.where(on, wgt, 0.0)
        return wgt / wgt.sum() * s

    corner = np.all(at_lo, axis=1)
    for a in range(dim):
        free = np.ones((n, dim), bool)
        free[at_lo[:, a], a] = False
        others = [c for c in range(dim) if c != a]
        free[corner, :] = False
        if dim == 3:  # a second corner on the min face, fixed in one component
            c2 = at_lo[:, a] & at_hi[:, others[0]] & at_lo[:, others[1]]
            free[c2, others[1]] = False
        f = np.zeros((n, dim))
        f[:, a] = face_force(a)
        names.append(f"stretch-{AXES[a]}")
        frees.append(free.ravel())
        forces.append(f.ravel())
    for a, b in itertools.permutations(range(dim), 2):
        free = np.ones((n, dim), bool)
        free[at_lo[:, b], :] = False
        f = np.zeros((n, dim))
        f[:, a] = face_force(b)
        names.append(f"shear-{AXES[a]}{AXES[b]}" if dim == 3 else f"shear-{AXES[a]}")
        frees.append(free.ravel())
        forces.append(f.ravel())
    return names, np.array(frees), np.array(forces)


def solve_network(points, springs, k, free_masks, forces) -> np.ndarray:
    """Linear statics per load case (u = 0 on constrained dofs), shape (L, ndof)."""
    import scipy.sparse.linalg as spla

    B = incidence(points, springs)
    K = stiffness_matrix(B, k)
    U = np.zeros_like(np.asarray(forces, float))
    for i, (free, f) in enumerate(zip(free_masks, forces)):
        Kf = K[free][:, free].tocsc()
        U[i, free] = spla.splu(Kf).solve(f[free])
    return U


def recoverable_problem(
    shape,
    sigma: float = 0.3,
    seed: int = 0,
    grouped: bool = False,
    diagonals: str = "all",
    weights=None,
    spacing: float = 1.0,
):
    """A FitProblem whose reference comes from known perturbed constants (best G = 0).

    k0 = 1 per unit length (Deussen's E s0/4 up to a factor); the truth multiplies each
    constant (or each group's, when ``grouped``) by exp(sigma * N(0, 1)). Returns
    (problem, k_true).
    """
    points, springs, groups = grid_network(shape, spacing, diagonals)
    rng = np.random.default_rng(seed)
    L = np.linalg.norm(points[springs[:, 1]] - points[springs[:, 0]], axis=1)
    k0 = 1.0 / L
    if grouped:
        k_true = k0 * np.exp(sigma * rng.standard_normal(groups.max() + 1))[groups]
    else:
        k_true = k0 * np.exp(sigma * rng.standard_normal(len(k0)))
    names, frees, forces = basic_loads(points, s=float(np.prod(shape)) ** (1 / len(shape)))
    ndof = points.size
    w = np.ones(ndof) if weights is None else np.asarray(weights, float)
    g = groups if grouped else None
    blank = FitProblem.from_network(
        points, springs, k0, frees, forces, np.zeros_like(forces), w, names, groups=g
    )
    prob = blank.with_reference(blank.solve(k_true))  # fast solver (ND ordering); shares the setup
    return prob, k_true


def noisy(prob, noise: float, seed: int):
    """The problem with its reference perturbed by noise * rms(u_ref) N(0, 1) per load
    (seeded): the best G is then unknown but at most G(k_true)."""
    rng = np.random.default_rng(seed)
    return prob.with_reference(
        [
            b.u_ref
            + noise * float(np.sqrt(np.mean(b.u_ref**2))) * rng.standard_normal(len(b.u_ref))
            for b in prob.blocks
        ]
    )
