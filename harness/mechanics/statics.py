"""Linear statics of spring networks under the case's load cases (docs/design.md, "Clamps
and loads act on faces").

K = B diag(k) B^T (``harness.models.springs``). A load case fixes the listed displacement
components of the nodes on its constraint parts (``harness.case.parts.part_predicate``, the
same predicates the FEM reference uses) and turns tractions into the consistent nodal
forces of the same traction on the same boundary facets as the FEM's
(harness.case.facet_loads: a mesh body's own facets; a box's or polygon's faces tiled by
their nodes).

Gravity gives m_i g, a body force per volume b gives (m_i / rho) b. The arrays for the
optimiser come from :func:`load_arrays`. A mechanism or a floating node raises
``ModelError`` naming the nodes, never a singular-matrix traceback.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from harness.case.facet_loads import facet_forces, part_facets
from harness.case.loadsets import LoadCase, stress_field, stress_tensor
from harness.case.parts import part_predicate
from harness.errors import ModelError, naming
from harness.io.meshfile import mesh_surface
from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
from harness.models.springs import incidence, stiffness_matrix


def _predicate(case, part: str):
    return part_predicate(part, case.body.bbox(), case.body.parts)


def fixed_mask(points: np.ndarray, case, load) -> np.ndarray:
    """(n, dim) True where a displacement component is constrained to zero."""
    fixed = np.zeros(points.shape, bool)
    for c in load.constraints:
        on = _predicate(case, c.part)(points.T)
        if not on.any():
            raise ModelError(
                f"load '{load.name}': no node lies on constraint part '{c.part}'",
                field="model",
                fix="place nodes on that boundary (grid / random placements include the corners)",
            )
        for comp in c.components:
            fixed[on, comp] = True
    return fixed


def _facet_measure(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(size (m,), unit normal (m, dim) up to sign) of segments (m, 2, 2) or planar
    polygons (m, k, 3) given by their vertices in order."""
    if x.shape[2] == 2:
        d = x[:, 1] - x[:, 0]
        n = np.stack([d[:, 1], -d[:, 0]], axis=1)
        size = np.linalg.norm(d, axis=1)
        return size, n / size[:, None]
    a = np.zeros((len(x), 3))
    for i in range(1, x.shape[1] - 1):
        a += np.cross(x[:, i] - x[:, 0], x[:, i + 1] - x[:, 0]) / 2
    size = np.linalg.norm(a, axis=1)
    return size, a / size[:, None]


def stress_forces(points: np.ndarray, case, stress) -> np.ndarray:
    """Nodal forces (n, dim) of the traction sigma . n of a stress load on the body's
    whole boundary. ``stress``: the load case (its constant or linear field,
    harness.case.loadsets.stress_field) or a constant Voigt stress. Each boundary facet
    (a polygon's edges, a mesh body's boundary faces, a box's faces tiled by the nodes
    on them), whose vertices must be nodes, gives them the P1-consistent load
    of the traction t, linear over it: f_i = |F| / k (t_c + (t_i - t_c) / m), t_i its
    value at vertex i, t_c their mean, m = k + 1 on a simplex of k vertices (exact), 3
    on a quadrilateral (bilinear, exact on a parallelogram); a constant t gives each |F| t / k."""
    body = case.body
    if isinstance(stress, LoadCase):
        field = lambda x: stress_field(stress, x)  # noqa: E731
    else:
        if any(
            l.stress_gradient is not None and tuple(l.stress) == tuple(stress) for l in case.loads
        ):
            raise ModelError(
                "a linear stress state's nodal forces need its load case, not its constant part",
                field="loads",
                fix="call stress_forces(points, case, load)",
            )
        sigma = stress_tensor(stress)
        field = lambda x: np.broadcast_to(sigma, x.shape[:-1] + sigma.shape)  # noqa: E731
    if body.shape == "polygon":
        v = np.asarray(body.vertices, float)
        area = 0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
        v = v if area > 0 else v[::-1]
        facets = [np.stack([np.arange(len(v)), (np.arange(len(v)) + 1) % len(v)], axis=1)]
        corners, inside = v, [None]  # counter-clockwise: (dy, -dx) points out
    elif body.shape == "mesh":
        corners, facets, inside = mesh_surface(body.file, body.format)
    else:
        corners = np.asarray(points, float)
        facets, inside = _box_surface(corners, case)
    tol = 1e-8 * float(np.ptp(corners, axis=0).max())
    dist, node = cKDTree(points).query(corners)
    dim = points.shape[1]
    f = np.zeros(points.shape)
    for fac, cell_centre in zip(facets, inside):
        x = corners[fac]
        size, n = _facet_measure(x)
        # outwards, away from the facet's cell (cells may be numbered either way)
        if cell_centre is not None:
            n *= np.where(np.einsum("ij,ij->i", n, x.mean(axis=1) - cell_centre) < 0, -1.0, 1.0)[
                :, None
            ]
        k = fac.shape[1]
        t = np.einsum("mkab,mb->mka", field(x), n)  # traction at the facet's vertices
        tc = t.mean(axis=1, keepdims=True)
        share = (size / k)[:, None, None] * (tc + (t - tc) / (k + 1 if k <= dim else 3))
        used = np.unique(fac)
        if np.any(dist[used] > tol):
            raise ModelError(
                "the stress loads need a node at every vertex of the body's surface",
                field="model.placement",
                fix="use placement = 'mesh' (the mesh's own vertices)",
            )
        np.add.at(f, node[fac].ravel(), share.reshape(-1, dim))
    return f


def _box_surface(points: np.ndarray, case) -> tuple[list, list]:
    """([facets (m, k) node indices], [their cells' inside (m, dim)]) of a box's faces,
    each tiled by its nodes as a face traction's are (harness.case.facet_loads), which
    must cover it (its corners are nodes)."""
    lo, hi = case.body.bbox()
    dim = len(lo)
    out = []
    for a in range(dim):
        face = float(np.prod(np.delete(hi - lo, a)))
        for side in (0, 1):
            name = f"{'xyz'[a]}{side}"
            tiles = [f for f in part_facets(points, case, _predicate(case, name)) if len(f)]
            covered = sum(_facet_measure(points[f])[0].sum() for f in tiles)
            if abs(covered - face) > 1e-9 * face:
                raise ModelError(
                    f"a stress on the whole boundary needs nodes at the corners of face {name}",
                    field="model.placement",
                    fix="use a grid placement (its nodes include the corners)",
                )
            out += tiles
    return out, [np.broadcast_to((lo + hi) / 2, (len(f), dim)) for f in out]


def force_vector(network, case, load) -> np.ndarray:
    """Nodal forces (n, dim) of a load case: tractions through the part's facets
    (harness.case.facet_loads, the FEM's facets and integral), gravity m_i g, a body
    force (m_i / rho) b."""
    pts = network.points
    f = np.zeros(pts.shape)
    if load.stress is not None:
        f += stress_forces(pts, case, load)
    for t in load.tractions:
        fac = part_facets(pts, case, _predicate(case, t.part))
        if not any(len(a) for a in fac):
            raise ModelError(
                f"load '{load.name}': traction part '{t.part}' has no boundary facets",
                field="model",
                fix="put tractions on faces (2-D: edges) of the body, with nodes along them",
            )
        f += facet_forces(pts, fac, t.vector, t.twist)
    if load.gravity is not None:
        f += network.masses[:, None] * np.asarray(load.gravity, float)[None]
    if load.body_force is not None:
        f += (network.masses / case.material.density)[:, None] * np.asarray(load.body_force, float)[
            None
        ]
    return f


def load_arrays(network, case, load) -> tuple[np.ndarray, np.ndarray]:
    """(free_mask (ndof,), f (ndof,)) with dof = dim*node + component."""
    return ~fixed_mask(network.points, case, load).ravel(), force_vector(
        network, case, load
    ).ravel()


def all_load_arrays(network, case) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(names, free_masks (L, ndof) bool, forces (L, ndof)) of every load case: the
    arrays ``harness.optimize.problem.FitProblem.from_network`` takes."""
    names, frees, forces = [], [], []
    for load in case.loads:
        free, f = load_arrays(network, case, load)
        names.append(load.name)
        frees.append(free)
        forces.append(f)
    return names, np.array(frees), np.array(forces)


# -- solving -----------------------------------------------------------------------------


def _nodes(dofs, dim) -> list[int]:
    return sorted({int(d) // dim for d in dofs})


def _describe(nodes, points, limit=8) -> str:
    shown = ", ".join(f"{i} at ({', '.join(f'{x:.3g}' for x in points[i])})" for i in nodes[:limit])
    return shown + (f" and {len(nodes) - limit} more" if len(nodes) > limit else "")


def check_connected(points, springs, free: np.ndarray, name: str = ""):
    """Raise ModelError for nodes without springs and parts held by no constraint."""
    n, dim = points.shape
    deg = np.bincount(springs.ravel(), minlength=n)
    free2 = np.asarray(free, bool).reshape(n, dim)
    fixed_node = (~free2).any(axis=1)
    lonely = np.flatnonzero((deg == 0) & free2.any(axis=1))
    where = f"load '{name}': " if name else ""
    if len(lonely):
        raise ModelError(
            f"{where}floating nodes without springs: {_describe(list(lonely), points)}",
            field="model",
            fix="connect them or remove them",
        )
    g = sp.coo_matrix((np.ones(len(springs)), (springs[:, 0], springs[:, 1])), shape=(n, n))
    ncomp, lab = connected_components(g, directed=False)
    for c in range(ncomp):
        nodes = np.flatnonzero(lab == c)
        if not fixed_node[nodes].any():
            raise ModelError(
                f"{where}a group of {len(nodes)} nodes is held by no constraint: "
                f"{_describe(list(nodes), points)}",
                field="model",
                fix="connect it to the rest of the network",
            )


def _mechanism(K: sp.spmatrix, free_dofs: np.ndarray, points, name: str, rtol: float = 1e-9):
    """Raise a ModelError naming the nodes of the zero-energy modes of K (free block)."""
    dim = points.shape[1]
    nf = K.shape[0]
    where = f"load '{name}': " if name else ""
    if nf <= 3000:
        d = np.sqrt(np.maximum(K.diagonal(), 1e-300))
        Ks = (K.toarray() / d[:, None]) / d[None, :]
        lam, vec = np.linalg.eigh(Ks)
        null = lam <= rtol * max(lam[-1], 1e-300)
        amp = np.abs(vec[:, null]).max(axis=1) if null.any() else np.zeros(nf)
        dofs = free_dofs[amp > 1e-3 * max(amp.max(), 1e-300)]
        count = int(null.sum())
    else:
        dofs, count = free_dofs[K.diagonal() <= 0], -1
    nodes = _nodes(dofs, dim)
    modes = f"{count} zero-energy mode(s)" if count >= 0 else "a zero-energy mode"
    raise ModelError(
        f"{where}the spring network is a mechanism ({modes}); nodes that move freely: "
        f"{_describe(nodes, points)}",
        field="model",
        fix="add springs (e.g. diagonals: structure = 'structure1') or constraints",
    )


MULTIFRONTAL_MIN = 20_000  # free dofs from which a 3-D network is factorised by the multifrontal
# Cholesky (harness/linalg/multifrontal.py): SuperLU took 15 s per load set on a 50k-tet mesh


def _symmetric(K, rtol: float = 1e-12) -> bool:
    """K equals K^T to rounding (a Cholesky reads one triangle: harness/models/mt.py's K is
    not symmetric)."""
    return abs(K - K.T).max() <= rtol * max(abs(K).max(), 1e-300)


class _Factor:
    def __init__(self, K, free_dofs, points, name):
        self.K = K
        d = K.diagonal()
        if np.any(d <= 0):
            _mechanism(K, free_dofs, points, name)
        self.lu = None
        # else LU (B&C's MT)
        if points.shape[1] == 3 and K.shape[0] >= MULTIFRONTAL_MIN and _symmetric(K):
            coords = np.repeat(points, 3, axis=0)[free_dofs]  # each dof at its node
            try:
                self.chol = MultifrontalCholesky(K, _symbolic(K, coords), name)
                return
            except ModelError:  # not positive definite: a mechanism; name its nodes
                _mechanism(K, free_dofs, points, name)
        try:
            self.lu = spla.splu(K.tocsc())
        except RuntimeError:
            _mechanism(K, free_dofs, points, name)
        u = np.abs(self.lu.U.diagonal())
        # pivots relative to the matching diagonal entries (scale free)
        dd = d[self.lu.perm_c]
        if np.any(u <= 1e-10 * dd):
            _mechanism(K, free_dofs, points, name)

    def __call__(self, f):
        return self.lu.solve(f) if self.lu is not None else self.chol.solve(f)


def solve_arrays(points, springs, k, free: np.ndarray, f: np.ndarray, name: str = "") -> np.ndarray:
    """Displacements (ndof,) of K u = f on the free dofs, u = 0 elsewhere (plain arrays)."""
    points = np.asarray(points, float)
    springs = np.asarray(springs, int)
    free = np.asarray(free, bool)
    check_connected(points, springs, free, name)
    B = incidence(points, springs)
    K = stiffness_matrix(B, k)
    fd = np.flatnonzero(free)
    fac = _Factor(K[fd][:, fd], fd, points, name)
    u = np.zeros(len(free))
    u[fd] = fac(np.asarray(f, float)[fd])
    return u


@dataclass(frozen=True, eq=False)
class StaticsResult:
    """u (L, n, dim) displacements per load case ``names``; forces (L, n, dim);
    ``load_seconds`` (L,) the wall time of each load's factorisation and solve (loads that
    share one split it)."""

    names: tuple[str, ...]
    u: np.ndarray
    forces: np.ndarray
    load_seconds: np.ndarray | None = None

    @property
    def seconds(self) -> float:
        return float(np.sum(self.load_seconds)) if self.load_seconds is not None else float("nan")

    def displacement(self, load: str) -> np.ndarray:
        return self.u[self.names.index(load)]


def solve(network, case, loads=None) -> StaticsResult:
    """Equilibrium displacements of every load case (or the named ones); load cases with
    the same constraints share one factorisation. Errors name the case file."""
    return solve_all([network], case, loads)[0]


def solve_all(networks, case, loads=None) -> list[StaticsResult]:
    """:func:`solve` for networks on the same nodes, springs and masses (one mesh under
    several stiffness rules): the loads' arrays are made once, each constraint set's
    ordering and symbolic factorisation serve every network, and one numeric factor is
    alive at a time."""
    with naming(case):
        return _solve_all(list(networks), case, loads)


def _stiffness(network):
    K = stiffness_matrix(incidence(network.points, network.springs), network.k)
    if getattr(network, "volume", None) is not None:  # springs + volume: harness/models/volume.py
        K = K + network.volume.stiffness_matrix(network.points)
    return sp.csc_matrix(K)


def _solve_all(networks, case, loads=None) -> list[StaticsResult]:
    loads = [l for l in case.loads if loads is None or l.name in loads]
    if not loads:
        raise ModelError(
            "no load cases to solve",
            field="loads",
            fix="add [loads] set = 'basic2d' or [[loads.case]]",
        )
    first = networks[0]
    n, dim = first.points.shape
    arrays = [load_arrays(first, case, load) for load in loads]
    groups: dict = {}
    for i, (free, _) in enumerate(arrays):
        groups.setdefault(free.tobytes(), []).append(i)
    u = np.zeros((len(networks), len(loads), n * dim))
    seconds = np.zeros((len(networks), len(loads)))
    Ks = [None] * len(networks)
    for idx in groups.values():
        free = arrays[idx[0]][0]
        fd = np.flatnonzero(free)
        name = loads[idx[0]].name
        check_connected(first.points, first.springs, free, name)
        F = np.column_stack([arrays[i][1][fd] for i in idx])
        for j, net in enumerate(networks):
            t0 = time.perf_counter()
            if Ks[j] is None:
                Ks[j] = _stiffness(net)
            x = _Factor(Ks[j][fd][:, fd], fd, first.points, name)(F)
            u[j][np.ix_(idx, fd)] = x.T
            seconds[j, idx] = (time.perf_counter() - t0) / len(idx)
    forces = np.array([f.reshape(n, dim) for _, f in arrays])
    names = tuple(l.name for l in loads)
    return [
        StaticsResult(names, u[j].reshape(len(loads), n, dim), forces, seconds[j])
        for j in range(len(networks))
    ]


_SYMBOLIC: dict = {}  # the multifrontal Cholesky's symbolic factorisations by pattern and dof
# locations: the networks of one mesh under different stiffness rules share them (a 104k-dof
# network of a 200k-tet mesh: ~2 s and ~0.5 GB each; solve_all uses each one in a row)
SYMBOLIC_KEEP = 2


def _symbolic(K, coords):
    """The multifrontal Symbolic of K's pattern with these dof locations (cached, see _SYMBOLIC)."""

    A = sp.csr_matrix(K)
    A.sort_indices()
    h = hashlib.sha1()
    for a in (np.asarray(A.shape), A.indptr, A.indices, coords):
        h.update(np.ascontiguousarray(a).tobytes())
    key = h.hexdigest()
    if key not in _SYMBOLIC:
        if len(_SYMBOLIC) >= SYMBOLIC_KEEP:
            _SYMBOLIC.pop(next(iter(_SYMBOLIC)))
        _SYMBOLIC[key] = Symbolic(A, coords)
    return _SYMBOLIC[key]
