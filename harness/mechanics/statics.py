"""Linear statics of spring networks under the case's load cases (DESIGN.md).

K = B diag(k) B^T (``harness.models.springs``). A load case fixes the listed displacement
components of the nodes on its constraint parts (``harness.case.parts.part_predicate``, the
same predicates the FEM reference uses) and turns tractions into nodal forces:

- 2-D: the part's nodes in order along the part; each segment between neighbours gives
  half its length times the traction to each end (the integral of a constant traction
  against piecewise-linear hat functions).
- 3-D: the part's nodes projected to the face plane; on a tensor grid each node gets the
  product of its 1-D tributary lengths (bilinear hats), otherwise the nodes are
  triangulated (Delaunay in the plane) and each triangle gives area/3 to its vertices.

Gravity gives m_i g, a body force per volume b gives (m_i / rho) b. The arrays for the
optimiser come from :func:`load_arrays`. A mechanism or a floating node raises
``ModelError`` naming the nodes, never a singular-matrix traceback.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components
from scipy.spatial import Delaunay, cKDTree

from harness.errors import ModelError, naming
from harness.case.facet_loads import facet_forces, needs_facets, part_facets
from harness.case.parts import part_predicate
from harness.models.springs import incidence, stiffness_matrix


def _predicate(case, part: str):
    return part_predicate(part, case.body.bbox(), case.body.parts)


def fixed_mask(points: np.ndarray, case, load) -> np.ndarray:
    """(n, dim) True where a displacement component is constrained to zero."""
    fixed = np.zeros(points.shape, bool)
    for c in load.constraints:
        on = _predicate(case, c.part)(points.T)
        if not on.any():
            raise ModelError(f"load '{load.name}': no node lies on constraint part '{c.part}'", field="model",
                             fix="place nodes on that boundary (grid / random placements include the corners)")
        for comp in c.components:
            fixed[on, comp] = True
    return fixed


def _tributary_1d(s: np.ndarray) -> np.ndarray:
    """Half the distance to each neighbour along a sorted coordinate."""
    seg = np.diff(s)
    t = np.zeros(len(s))
    t[:-1] += seg / 2
    t[1:] += seg / 2
    return t


def tributary_measure(points: np.ndarray, on_part) -> np.ndarray:
    """Per node (n,) length (2-D) or area (3-D) of the part it carries; see the module doc.
    ``on_part`` maps points (dim, m) to a mask (the part predicate)."""
    n, dim = points.shape
    idx = np.flatnonzero(on_part(points.T))
    out = np.zeros(n)
    if len(idx) < dim:
        return out
    q = points[idx]
    c = q - q.mean(0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    if dim == 2:
        s = c @ vt[0]
        order = np.argsort(s)
        seg_mid = (q[order[:-1]] + q[order[1:]]) / 2
        ok = on_part(seg_mid.T)
        L = np.diff(s[order]) * ok
        t = np.zeros(len(idx))
        t[:-1] += L / 2
        t[1:] += L / 2
        out[idx[order]] = t
        return out
    uv = c @ vt[:2].T
    # a face of an axis-aligned box: use the two axes of the plane directly (exact tensor test)
    normal = np.argmax(np.abs(vt[2]))
    if np.isclose(abs(vt[2][normal]), 1.0):
        uv = q[:, [a for a in range(3) if a != normal]]
    ru = np.unique(np.round(uv[:, 0], 12))
    rv = np.unique(np.round(uv[:, 1], 12))
    if len(ru) * len(rv) == len(idx) and len(ru) > 1 and len(rv) > 1:
        tu, tv = _tributary_1d(ru), _tributary_1d(rv)
        iu = np.searchsorted(ru, np.round(uv[:, 0], 12))
        iv = np.searchsorted(rv, np.round(uv[:, 1], 12))
        out[idx] = tu[iu] * tv[iv]
        return out
    try:
        tri = Delaunay(uv).simplices
    except Exception:
        return out
    cent = q[tri].mean(axis=1)
    tri = tri[on_part(cent.T)]
    a = uv[tri]
    e1, e2 = a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    np.add.at(out, idx[tri.ravel()], np.repeat(area / 3, 3))
    return out


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


def stress_forces(points: np.ndarray, case, voigt) -> np.ndarray:
    """Nodal forces (n, dim) of the traction sigma . n of a homogeneous stress on the
    body's whole boundary: each boundary facet (a polygon's edges, a mesh body's boundary
    faces) gives sigma . n times its size equally to its vertices, which must be nodes."""
    from harness.case.loadsets import stress_tensor
    from harness.io.meshfile import mesh_surface
    body = case.body
    if body.shape == "polygon":
        v = np.asarray(body.vertices, float)
        area = 0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
        v = v if area > 0 else v[::-1]
        facets = [np.stack([np.arange(len(v)), (np.arange(len(v)) + 1) % len(v)], axis=1)]
        corners, inside = v, [None]          # counter-clockwise: (dy, -dx) points out
    elif body.shape == "mesh":
        corners, facets, inside = mesh_surface(body.file, body.format)
    else:
        raise ModelError("a homogeneous stress on the whole boundary needs a polygon or mesh body", field="loads",
                         fix="boxes get the homogeneous sets as face tractions")
    sigma = stress_tensor(voigt)
    tol = 1e-8 * float(np.ptp(corners, axis=0).max())
    dist, node = cKDTree(points).query(corners)
    f = np.zeros(points.shape)
    for fac, cell_centre in zip(facets, inside):
        x = corners[fac]
        size, n = _facet_measure(x)
        if body.shape == "mesh":   # outwards, away from the facet's cell (cells may be numbered either way)
            n *= np.where(np.einsum("ij,ij->i", n, x.mean(axis=1) - cell_centre) < 0, -1.0, 1.0)[:, None]
        share = (size / fac.shape[1])[:, None] * (n @ sigma.T)
        used = np.unique(fac)
        if np.any(dist[used] > tol):
            raise ModelError("the homogeneous loads need a node at every vertex of the body's surface",
                             field="model.placement", fix="use placement = 'mesh' (the mesh's own vertices)")
        np.add.at(f, node[fac].ravel(), np.repeat(share, fac.shape[1], axis=0))
    return f


def force_vector(network, case, load) -> np.ndarray:
    """Nodal forces (n, dim) of a load case."""
    pts = network.points
    f = np.zeros(pts.shape)
    if load.stress is not None:
        f += stress_forces(pts, case, load.stress)
    for t in load.tractions:
        if needs_facets(case, t):       # a mesh group or a twist: on the part's facets (harness/case/facet_loads.py)
            fac = part_facets(pts, case, _predicate(case, t.part))
            if not any(len(a) for a in fac):
                raise ModelError(f"load '{load.name}': traction part '{t.part}' has no boundary facets", field="model",
                                 fix="put tractions on faces (2-D: edges) of the body")
            f += facet_forces(pts, fac, t.vector, t.twist)
            continue
        meas = tributary_measure(pts, _predicate(case, t.part))
        if not np.any(meas > 0):
            raise ModelError(f"load '{load.name}': traction part '{t.part}' holds too few nodes to carry a traction",
                             field="model", fix="place nodes along that boundary")
        f += meas[:, None] * np.asarray(t.vector, float)[None]
    if load.gravity is not None:
        f += network.masses[:, None] * np.asarray(load.gravity, float)[None]
    if load.body_force is not None:
        f += (network.masses / case.material.density)[:, None] * np.asarray(load.body_force, float)[None]
    return f


def load_arrays(network, case, load) -> tuple[np.ndarray, np.ndarray]:
    """(free_mask (ndof,), f (ndof,)) with dof = dim*node + component."""
    return ~fixed_mask(network.points, case, load).ravel(), force_vector(network, case, load).ravel()


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
        raise ModelError(f"{where}floating nodes without springs: {_describe(list(lonely), points)}",
                         field="model", fix="connect them or remove them")
    g = sp.coo_matrix((np.ones(len(springs)), (springs[:, 0], springs[:, 1])), shape=(n, n))
    ncomp, lab = connected_components(g, directed=False)
    for c in range(ncomp):
        nodes = np.flatnonzero(lab == c)
        if not fixed_node[nodes].any():
            raise ModelError(f"{where}a group of {len(nodes)} nodes is held by no constraint: {_describe(list(nodes), points)}",
                             field="model", fix="connect it to the rest of the network")


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
    raise ModelError(f"{where}the spring network is a mechanism ({modes}); nodes that move freely: "
                     f"{_describe(nodes, points)}", field="model",
                     fix="add springs (e.g. diagonals: structure = 'structure1') or constraints")


MULTIFRONTAL_MIN = 20_000   # free dofs from which a 3-D network is factorised by the multifrontal
# Cholesky (harness/linalg/multifrontal.py): SuperLU took 15 s per load set on a 50k-tet mesh


def _symmetric(K, rtol: float = 1e-12) -> bool:
    """K equals K^T to rounding (a Cholesky reads one triangle: harness/models/mt.py's K is not symmetric)."""
    return abs(K - K.T).max() <= rtol * max(abs(K).max(), 1e-300)


class _Factor:
    def __init__(self, K, free_dofs, points, name):
        self.K = K
        d = K.diagonal()
        if np.any(d <= 0):
            _mechanism(K, free_dofs, points, name)
        self.lu = None
        if points.shape[1] == 3 and K.shape[0] >= MULTIFRONTAL_MIN and _symmetric(K):   # else LU (B&C's MT)
            from harness.linalg.multifrontal import MultifrontalCholesky
            coords = np.repeat(points, 3, axis=0)[free_dofs]    # each dof at its node
            try:
                self.chol = MultifrontalCholesky(K, _symbolic(K, coords), name)
                return
            except ModelError:          # not positive definite: a mechanism; name its nodes
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
    """u (L, n, dim) displacements per load case ``names``; forces (L, n, dim)."""
    names: tuple[str, ...]
    u: np.ndarray
    forces: np.ndarray

    def displacement(self, load: str) -> np.ndarray:
        return self.u[self.names.index(load)]


def solve(network, case, loads=None) -> StaticsResult:
    """Equilibrium displacements of every load case (or the named ones); load cases with
    the same constraints share one factorisation. Errors name the case file."""
    with naming(case):
        return _solve(network, case, loads)


def _solve(network, case, loads=None) -> StaticsResult:
    loads = [l for l in case.loads if loads is None or l.name in loads]
    if not loads:
        raise ModelError("no load cases to solve", field="loads", fix="add [loads] set = 'basic2d' or [[loads.case]]")
    B = incidence(network.points, network.springs)
    K = stiffness_matrix(B, network.k)
    if getattr(network, "volume", None) is not None:    # springs + volume: harness/models/volume.py
        K = (K + network.volume.stiffness_matrix(network.points)).tocsc()
    n, dim = network.points.shape
    us, fs, facs = [], [], {}
    for load in loads:
        free, f = load_arrays(network, case, load)
        key = free.tobytes()
        fd = np.flatnonzero(free)
        if key not in facs:
            check_connected(network.points, network.springs, free, load.name)
            facs[key] = _Factor(K[fd][:, fd], fd, network.points, load.name)
        u = np.zeros(n * dim)
        u[fd] = facs[key](f[fd])
        us.append(u.reshape(n, dim))
        fs.append(f.reshape(n, dim))
    return StaticsResult(tuple(l.name for l in loads), np.array(us), np.array(fs))


_SYMBOLIC: dict = {}        # the multifrontal Cholesky's symbolic factorisations by pattern and dof
# locations: the networks of one mesh under different stiffness rules share them (50k-tet mesh:
# ~1.5 s CPU each, 10 a calibration)


def _symbolic(K, coords):
    """The multifrontal Symbolic of K's pattern with these dof locations (cached, see _SYMBOLIC)."""
    import hashlib
    from harness.linalg.multifrontal import Symbolic
    A = sp.csr_matrix(K)
    A.sort_indices()
    h = hashlib.sha1()
    for a in (np.asarray(A.shape), A.indptr, A.indices, coords):
        h.update(np.ascontiguousarray(a).tobytes())
    key = h.hexdigest()
    if key not in _SYMBOLIC:
        if len(_SYMBOLIC) >= 4:
            _SYMBOLIC.pop(next(iter(_SYMBOLIC)))
        _SYMBOLIC[key] = Symbolic(A, coords)
    return _SYMBOLIC[key]
