"""The held-out study's judge, independent of springbench's FEM and statics: the study's
loads, the truth (P2 with scikit-fem on the body's mesh, or on it refined once, that system
solved by springbench's sparse Cholesky and each solution checked by its residual on
scikit-fem's matrix: only the linear algebra is shared, and it is verified) and the
exported JSON's linear statics assembled here (springs, volume terms, kn terms; bench tets:
linear tetrahedra with an export's per-tet E, nu or the plain material)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.bench.heldout_bodies import Body
from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic

E, RHO = 1e5, 1000.0


@dataclass(frozen=True)
class Load:
    """traction(x) (3, ...) -> (3, ...) on the load group, or a gravity vector; held: the
    groups whose nodes are held."""

    name: str
    held: tuple
    traction: object = None
    gravity: tuple | None = None


def face_frame(points, tris):
    """(area-weighted centroid (3,), unit normal (3,), area) of a planar group."""
    x = points[tris]
    a = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]) / 2
    area = np.linalg.norm(a, axis=1)
    c = (x.mean(axis=1) * area[:, None]).sum(0) / area.sum()
    n = a.sum(0)
    return c, n / np.linalg.norm(n), area.sum()


def constant(d):
    """The traction field t(x) = d (x: (3, ...) -> (3, ...))."""
    d = np.asarray(d, float)
    return lambda x: np.broadcast_to(d.reshape((3,) + (1,) * (x.ndim - 1)), x.shape)


def twisting(axis, centre):
    """The traction field t(x) = axis x (x - centre)."""
    a, c = np.asarray(axis, float), np.asarray(centre, float)
    return lambda x: np.cross(a, x - c.reshape((3,) + (1,) * (x.ndim - 1)), axis=0)


def study_loads(body: Body, points, groups) -> list[Load]:
    """The study's loads of a body (unit magnitudes; scaled by the truth later)."""
    c, n, _ = face_frame(points, groups["load"])
    return [
        Load("shear_a", ("clamp",), constant(body.across[0])),
        Load("shear_b", ("clamp",), constant(body.across[1])),
        Load("twist", ("clamp",), twisting(n, c)),
        Load("gravity", ("clamp",), gravity=body.gravity),
        Load("gravity_2", ("clamp", "load"), gravity=body.gravity),
    ]


# -- truth: P2, scikit-fem -----------------------------------------------------------------


def _key(tri: np.ndarray, n: int) -> np.ndarray:
    s = np.sort(np.asarray(tri, np.int64), axis=1)
    return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]


def truth(points, tets, groups, loads, nu, rho=RHO, refine=False):
    """{load: (u at the vertices (n, 3), strain peak)} of the P2 solution, each load at unit
    magnitude; the P2 mesh is ``tets`` refined once (refine: solved by a sparse Cholesky,
    every solution checked by its residual) or itself (SuperLU)."""
    from skfem import Basis, ElementTetP2, ElementVector, FacetBasis, LinearForm, MeshTet, asm
    from skfem.helpers import dot, sym_grad
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    n = len(points)
    coarse = MeshTet(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T))
    mesh = coarse.refined() if refine else coarse
    parents = np.repeat(np.arange(n)[:, None], 2, axis=1)
    if refine:  # vertex n + j is the midpoint of coarse edge j
        assert np.allclose(mesh.p[:, n:], coarse.p[:, coarse.edges].mean(axis=1))
        parents = np.vstack([parents, coarse.edges.T])
    bf = mesh.boundary_facets()
    fv = parents[mesh.facets[:, bf].T].reshape(len(bf), -1)  # each boundary facet's parents
    fv = np.sort(fv, axis=1)
    distinct = np.c_[fv[:, :1], np.where(np.diff(fv, axis=1) > 0, fv[:, 1:], -1)]
    tri = np.sort(distinct, axis=1)[:, -3:]  # its parent triangle's vertices
    keys = _key(tri, n)

    def facets(group):
        return bf[np.isin(keys, _key(groups[group], n))]

    lam, mu = lame_parameters(E, nu)
    e = ElementVector(ElementTetP2())
    basis = Basis(mesh, e, intorder=4)
    K = asm(linear_elasticity(lam, mu), basis).tocsc()
    out, lus = {}, {}
    for load in loads:
        if load.held not in lus:
            held = np.unique(
                np.concatenate([basis.get_dofs(facets=facets(g)).all() for g in load.held])
            )
            free = np.setdiff1d(np.arange(basis.N), held)
            A = K[free][:, free]
            solve = _cholesky(A, basis.doflocs[:, free].T) if refine else _lu(A)
            lus[load.held] = (free, solve)
        free, lu = lus[load.held]
        if load.traction is not None:
            fb = FacetBasis(mesh, e, facets=facets("load"), intorder=4)
            b = asm(LinearForm(lambda v, w: dot(load.traction(w.x), v)), fb)
        else:
            g = rho * np.asarray(load.gravity, float)
            b = asm(LinearForm(lambda v, w: g[0] * v[0] + g[1] * v[1] + g[2] * v[2]), basis)
        u = np.zeros(basis.N)
        u[free] = lu(b[free])
        eps = sym_grad(basis.interpolate(u))
        peak = np.percentile(np.sqrt(np.einsum("ij...,ij...->...", eps, eps)), 99)
        out[load.name] = (u[basis.nodal_dofs[:, :n]].T.copy(), float(peak))
    return out


RESIDUAL = 1e-8  # the refined truth's largest relative residual (measured 1e-11..2e-10)


def _lu(A):
    return spla.splu(A, permc_spec="MMD_AT_PLUS_A").solve


def _cholesky(A, coords):
    """A solve of the SPD ``A`` by a sparse Cholesky (the refined P2's ~110k dofs: ~15 s, where
    SuperLU took over ten minutes); each solution checked by its residual on ``A`` itself."""
    A = sp.csr_matrix(A)
    chol = MultifrontalCholesky(A, Symbolic(A, coords))

    def solve(b):
        x = chol.solve(b)
        r = np.linalg.norm(A @ x - b) / np.linalg.norm(b)
        if not r <= RESIDUAL:
            raise RuntimeError(f"the P2 truth's solve has a relative residual {r:.1e}")
        return x

    return solve


# -- the exported network's statics --------------------------------------------------------


def network_stiffness(data: dict) -> sp.csr_matrix:
    """K (3n, 3n) of an exported model at rest: springs, volume terms (per element or per node),
    kn terms."""
    x = np.asarray(data["particle_q"], float)
    n = len(x)
    s = np.asarray(data["spring_indices"], int)
    d = x[s[:, 1]] - x[s[:, 0]]
    L = np.linalg.norm(d, axis=1)
    b = d / L[:, None]
    G = _rows(np.c_[-b, b], s, n)  # (springs, 3n): dl/du
    K = G.T @ sp.diags(np.asarray(data["spring_stiffness"], float)) @ G
    if "volume_indices" in data:  # kv/2 (V - V0)^2 / V0 per element
        kv = np.asarray(data["volume_stiffness"], float) / np.asarray(data["volume_rest"], float)
        Gv = _volume_rows(x, np.asarray(data["volume_indices"], int))
        K = K + Gv.T @ sp.diags(kv) @ Gv
    if "node_volume_elements" in data:  # kv_a/2 dV_a^2 / V0_a per node
        t = np.asarray(data["node_volume_elements"], int)
        a = np.asarray(data["node_volume_nodes"], int)
        where = np.full(n, -1)
        where[a] = np.arange(len(a))
        share = sp.csr_matrix(
            (np.full(t.size, 0.25), (where[t.ravel()], np.repeat(np.arange(len(t)), 4))),
            shape=(len(a), len(t)),
        )
        Gn = share @ _volume_rows(x, t)  # dV_a/du
        kv = np.asarray(data["node_volume_stiffness"], float) / np.asarray(
            data["node_volume_rest"], float
        )
        K = K + Gn.T @ sp.diags(kv) @ Gn
    if "kn_nodes" in data:  # kn_a/2 V_a d^2 s_a^2 per node
        a = np.asarray(data["kn_nodes"], int)
        where = np.full(n, -1)
        where[a] = np.arange(len(a))
        ends, spring = s.T.ravel(), np.tile(np.arange(len(s)), 2)
        on = where[ends] >= 0
        S = sp.csr_matrix(
            (np.ones(on.sum()), (where[ends[on]], spring[on])), shape=(len(a), len(s))
        )
        # ds_a/du
        H = sp.diags(1 / np.asarray(data["kn_spring_count"], float)) @ S @ sp.diags(1 / L) @ G
        c = (
            np.asarray(data["kn_stiffness"], float)
            * np.asarray(data["kn_node_volume"], float)
            * 9.0
        )
        K = K + H.T @ sp.diags(c) @ H
    return sp.csr_matrix(K)


def _volume_rows(x: np.ndarray, t: np.ndarray) -> sp.csr_matrix:
    """(m, 3n): dV_e/du of the tetrahedra t at positions x."""
    e = x[t[:, 1:]] - x[t[:, :1]]
    g = (
        np.stack(
            [np.cross(e[:, 1], e[:, 2]), np.cross(e[:, 2], e[:, 0]), np.cross(e[:, 0], e[:, 1])], 1
        )
        / 6
    )
    return _rows(np.c_[-g.sum(1), g.reshape(len(t), 9)], t, len(x))


def _rows(blocks: np.ndarray, nodes: np.ndarray, n: int) -> sp.csr_matrix:
    """(m, 3n) sparse rows: row r holds blocks[r, 3j:3j+3] at the dofs of node nodes[r, j]."""
    m, k = nodes.shape
    cols = (3 * nodes[:, :, None] + np.arange(3)).reshape(m, 3 * k)
    return sp.csr_matrix(
        (blocks.ravel(), (np.repeat(np.arange(m), 3 * k), cols.ravel())), shape=(m, 3 * n)
    )


def traction_forces(points, tris, traction) -> np.ndarray:
    """(n, 3) P1-consistent nodal forces of a traction linear over each triangle:
    f_i = A/3 (t_c + (t_i - t_c)/4), t_i its value at vertex i, t_c their mean."""
    x = points[tris]
    area = np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1) / 2
    t = np.moveaxis(traction(np.moveaxis(x, 2, 0)), 0, 2)  # (m, 3 vertices, 3)
    tc = t.mean(axis=1, keepdims=True)
    f = np.zeros(points.shape)
    np.add.at(f, tris.ravel(), ((area / 3)[:, None, None] * (tc + (t - tc) / 4)).reshape(-1, 3))
    return f


def model_solve(K, held: np.ndarray, f: np.ndarray) -> np.ndarray:
    """u (n, 3) of K u = f with the nodes ``held`` (indices) fixed."""
    n = len(f)
    fixed = np.zeros((n, 3), bool)
    fixed[held] = True
    free = np.flatnonzero(~fixed.ravel())
    u = np.zeros(3 * n)
    u[free] = spla.spsolve(sp.csc_matrix(K[free][:, free]), f.ravel()[free])
    return u.reshape(n, 3)


def model_answers(data: dict, points, groups, loads, scale: dict) -> dict:
    """{load: u (n, 3) at the mesh's vertices} of an exported model under the study's
    loads (each times scale[load]); its particles are matched to the vertices."""
    from scipy.spatial import cKDTree

    q = np.asarray(data["particle_q"], float)
    dist, order = cKDTree(q).query(points)
    if (
        len(q) != len(points)
        or len(np.unique(order)) != len(q)
        or np.max(dist) > 1e-9 * np.ptp(points, 0).max()
    ):
        raise ValueError("the model's particles are not the mesh's vertices")
    K = network_stiffness(data)
    m = np.asarray(data["particle_mass"], float)
    out = {}
    for load in loads:
        if load.traction is not None:
            f = traction_forces(points, groups["load"], load.traction)
        else:
            f = m[order][:, None] * np.asarray(load.gravity, float)[None]
        held = order[np.unique(np.concatenate([groups[g].ravel() for g in load.held]))]
        f_model = np.zeros_like(f)
        f_model[order] = f
        out[load.name] = scale[load.name] * model_solve(K, held, f_model)[order]
    return out


# -- linear tetrahedra (an export's tet_indices, tet_E, tet_nu; or the plain material) -----


def tet_stiffness(points, tets, E, nu) -> sp.csr_matrix:
    """K (3n, 3n) of linear tetrahedra, each with its own isotropic (E, nu):
    K_e[(a,i),(b,j)] = V (lambda g_ai g_bj + mu g_aj g_bi + mu delta_ij g_a . g_b), g_a the
    constant gradient of corner a's shape function (Lame form, not springbench's Voigt B^T D B)."""
    x = points[tets]
    A = x[:, 1:] - x[:, :1]  # rows: edges from corner 0; A @ [g_1 g_2 g_3] = I
    g = np.empty((len(tets), 4, 3))
    g[:, 1:] = np.transpose(np.linalg.inv(A), (0, 2, 1))
    g[:, 0] = -g[:, 1:].sum(axis=1)
    V = np.abs(np.linalg.det(A)) / 6
    E, nu = np.broadcast_to(E, V.shape), np.broadcast_to(nu, V.shape)
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    Ke = (
        lam[:, None, None, None, None] * np.einsum("mai,mbj->maibj", g, g)
        + mu[:, None, None, None, None] * np.einsum("maj,mbi->maibj", g, g)
        + (mu[:, None, None] * np.einsum("mak,mbk->mab", g, g))[:, :, None, :, None]
        * np.eye(3)[None, None, :, None, :]
    ) * V[:, None, None, None, None]
    dofs = (3 * tets[:, :, None] + np.arange(3)).reshape(len(tets), 12)
    n = 3 * len(points)
    return sp.csr_matrix(
        (
            Ke.reshape(len(tets), 12, 12).ravel(),
            (np.repeat(dofs, 12, axis=1).ravel(), np.tile(dofs, (1, 12)).ravel()),
        ),
        shape=(n, n),
    )


def tet_gravity(points, tets, gravity, rho=RHO) -> np.ndarray:
    """(n, 3) nodal gravity forces: rho V_e / 4 g at each corner of every tetrahedron (the
    lumped P1 mass a tet engine uses; for a constant g also the consistent P1 load)."""
    x = points[tets]
    V = np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6
    m = np.zeros(len(points))
    np.add.at(m, tets.ravel(), np.repeat(rho * V / 4, 4))
    return m[:, None] * np.asarray(gravity, float)[None]


def tet_solve(points, tets, groups, loads, scale: dict, E, nu, rho=RHO) -> dict:
    """{load: u (n, 3)} of linear tetrahedra with per-tet (E, nu) under the study's loads
    (times scale[load]): P1-consistent tractions on the load group's facets, lumped gravity
    (tet_gravity), the held groups' nodes fixed, one sparse LU per support."""
    K = tet_stiffness(points, tets, E, nu).tocsc()
    n = len(points)
    out, lus = {}, {}
    for load in loads:
        if load.held not in lus:
            fixed = np.zeros((n, 3), bool)
            fixed[np.unique(np.concatenate([groups[g].ravel() for g in load.held]))] = True
            free = np.flatnonzero(~fixed.ravel())
            lus[load.held] = (free, spla.splu(K[free][:, free].tocsc()))
        free, lu = lus[load.held]
        if load.traction is not None:
            f = traction_forces(points, groups["load"], load.traction)
        else:
            f = tet_gravity(points, tets, load.gravity, rho)
        u = np.zeros(3 * n)
        u[free] = lu.solve(f.ravel()[free])
        out[load.name] = scale[load.name] * u.reshape(n, 3)
    return out


def export_materials(data: dict, points, tets, source: str = "the export"):
    """(E (m,), nu (m,)) of an export's tetrahedra in the order of the body's ``tets``: its
    particles are matched to the vertices and its tet_indices rows (any order, any corner
    order) to the body's tetrahedra, which they must be exactly; else ValueError."""
    from scipy.spatial import cKDTree

    where = f"{source}: "
    for key in ("particle_q", "tet_indices", "tet_E", "tet_nu"):
        if data.get(key) is None:
            raise ValueError(f"{where}no {key}; export a tetrahedral model (--model p1-global, p1)")
    q = np.asarray(data["particle_q"], float)
    dist, order = cKDTree(q).query(points)
    if (
        len(q) != len(points)
        or len(np.unique(order)) != len(q)
        or np.max(dist) > 1e-9 * np.ptp(points, 0).max()
    ):
        raise ValueError(f"{where}particle_q are not the mesh's vertices; calibrate this mesh")
    vertex = np.empty(len(q), int)
    vertex[order] = np.arange(len(q))  # particle -> vertex
    t = np.asarray(data["tet_indices"])
    if t.ndim != 2 or t.shape[1] != 4 or t.min() < 0 or t.max() >= len(q):
        raise ValueError(f"{where}tet_indices must be (m, 4) indices into particle_q")
    both = np.sort(np.vstack([tets, vertex[t]]), axis=1)
    ids = np.unique(both, axis=0, return_inverse=True)[1].ravel()  # one id per distinct tet
    mine, theirs = ids[: len(tets)], ids[len(tets) :]
    if len(t) != len(tets) or not np.array_equal(np.sort(mine), np.sort(theirs)):
        raise ValueError(
            f"{where}tet_indices ({len(t)} rows) are not the mesh's {len(tets)} tetrahedra "
            "(each once); calibrate this mesh with its own cells"
        )
    row = np.empty(ids.max() + 1, int)
    row[theirs] = np.arange(len(t))  # a distinct tet's row in the export
    out = []
    for key in ("tet_E", "tet_nu"):
        v = np.asarray([np.nan if a is None else a for a in data[key]], float)
        if v.shape != (len(t),) or not np.isfinite(v).all():
            raise ValueError(
                f"{where}{key} must hold one finite value per tet_indices row ({len(t)})"
            )
        out.append(v[row[mine]])
    E, nu = out
    if (E <= 0).any() or (nu <= -1).any() or (nu >= 0.5).any():
        raise ValueError(f"{where}tet_E must be > 0 and tet_nu in (-1, 0.5)")
    return E, nu
