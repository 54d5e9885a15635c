"""Initial spring constants: named rules, each scored as a baseline.

2-D networks have unit thickness t = 1 (tractions are forces per length), so k has the
units of E. ``E_dir(x, n)`` is the material's Young's modulus along the spring
direction n at x, 1 / (a^T S a) with a = Voigt(n n^T) and S the (plane) compliance;
it is E for isotropic material and follows fibres and regions.

"deussen"    Deussen, Kobbelt & Tuecke 1995, Sect. 5.2: k = E s0 / 4 (a heuristic; exact
             for no lattice; s0 = rest length).
"uniform"    every spring the mean of the "deussen" constants (van Gelder's counter-
             example: equal stiffness fails for irregular meshes).
"vangelder"  van Gelder 1998 (J. Graphics Tools 3(2)), simplest form: k_c = sum over the
             cells T containing edge c of E |T| / |c|^2 (|T| area in 2-D, volume in 3-D).
             Exact in 2-D on the equilateral triangle lattice for nu = 1/3 (plane stress):
             there k = E sqrt(3)/2 (two triangles of area sqrt(3)/4 L^2), which is the
             Cauchy-Born value; van Gelder shows no rule is exact on general meshes. A
             grid quad counts as its triangulation by the diagonal springs (both
             diagonals: the average of the two triangulations; on the square lattice
             k_edge = E, k_diag = E/4); hexahedra and tetrahedra use k = E sum |T| / |c|^2
             with volumes, his 3-D analogue, exact for no lattice we test.
"lloyd"      Lloyd, Szekely & Harders 2007 (IEEE TVCG 13(5)): spring constants that match
             the FEM element stiffness matrix. Per cell we fit the constants of the cell's
             springs to the linear FEM stiffness (P1 triangles/tetrahedra, Q1 quads/hex,
             2x2(x2) Gauss) in the least-squares (Frobenius) sense, sum over the cells
             sharing a spring, and floor the (rare) non-positive sums at 1% of the median
             (obtuse triangles have negative best-fit constants). For an equilateral triangle and
             nu = 1/3 the
             match is exact and gives their closed form k = sqrt(3)/4 E t per triangle
             (derivation: spring energy sum k L^2 (n.eps.n)^2 / 2 over three directions 60
             deg apart is isotropic with lambda = mu = sqrt(3) k / (2 t); plane stress
             nu = 1/3 has lambda* = mu = 3E/8). Other nu, tetrahedra (whose six edge
             directions are only cubically symmetric) and quads are best fits, not exact.
             Anisotropic and inhomogeneous materials enter through the element C.
"cauchy"     ours: per cell, the constants whose Cauchy-Born (homogenised) stiffness
             (1/|T|) sum k L^2 n n n n best matches the material's C there (least squares,
             minimum norm; see harness/mechanics/homogenize.py), summed over the cells sharing a
             spring. On a grid this is the best periodic lattice, assembled cell-wise (so
             boundary springs get their cell share): exact for isotropic nu = 1/3 in 2-D
             plane stress and 1/4 in 3-D, the Cauchy floor otherwise.
"learned"    ours: van Gelder's constants times exp(sum_j c_j phi_j(e, nu)), phi_j cheap
             unit- and rotation-free features of the spring (1, nu - 0.3, (nu - 0.3)^2, its
             length relative to its neighbourhood's, on the surface or not, 3-D: the number of
             cells sharing it, the cells' mean dihedral angle at it (2-D: angle opposite it)
             and mean quality); c, a few numbers per dimension, fitted once by ``springbench
             rules fit`` on a corpus of gmsh meshes (cases/rules_corpus) at several nu against
             the exact linear stress states, shipped in harness/models/learned_rule.json (its
             record: the corpus's hashes, the command, the objective before and after). No FEM
             at use time. Quads and hexahedra get the fitted scale only. Details and the
             features' definitions: harness/models/learned_rule.py.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from harness.case.elasticity import element_stiffness
from harness.case.moments import _quadrature
from harness.errors import ModelError
from harness.models.learned_rule import learned as rule
from harness.models.springs import spring_directions
from harness.models.topology import element_pairs
from harness.registry import STIFFNESS_RULES

# each rule(points, springs, cells, material) -> k, registered by name
RULES = STIFFNESS_RULES.names()


def voigt_dyad(n: np.ndarray) -> np.ndarray:
    """Voigt vector of n n^T (stress convention): 2-D (xx, yy, xy), 3-D (xx, yy, zz, yz, xz, xy)."""
    n = np.atleast_2d(n)
    if n.shape[1] == 2:
        return np.stack([n[:, 0] ** 2, n[:, 1] ** 2, n[:, 0] * n[:, 1]], 1)
    x, y, z = n.T
    return np.stack([x * x, y * y, z * z, y * z, x * z, x * y], 1)


def directional_modulus(C: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Young's modulus along n for Voigt stiffness C (m, 3|6, 3|6) and unit n (m, dim)."""
    a = voigt_dyad(n)
    S = np.linalg.inv(C)
    return 1.0 / np.einsum("mi,mij,mj->m", a, S, a)


def deussen(points, springs, cells, material) -> np.ndarray:
    d, L = spring_directions(points, springs)
    mid = (points[springs[:, 0]] + points[springs[:, 1]]) / 2
    return directional_modulus(element_stiffness(material, mid), d) * L / 4


def uniform(points, springs, cells, material) -> np.ndarray:
    return np.full(len(springs), float(np.mean(deussen(points, springs, cells, material))))


def _cell_measure(points, c, ctype) -> np.ndarray:
    p = points[c]
    if ctype in ("triangle", "tetra"):
        return np.abs(np.linalg.det(p[:, 1:] - p[:, :1])) / (2 if ctype == "triangle" else 6)
    q, w = _quadrature(points, {ctype: c})
    per = {"quad": 6, "hexahedron": 24}[ctype]  # quadrature points per cell
    return w.reshape(len(c), per).sum(1)


def _spring_index(springs: np.ndarray):
    n = int(springs.max()) + 1
    key = springs[:, 0].astype(np.int64) * n + springs[:, 1]
    order = np.argsort(key)
    return n, key[order], order


def _lookup(index, a, b) -> np.ndarray:
    """Spring ids of node pairs (a, b) (any order); -1 where there is no spring."""
    n, keys, order = index
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    k = lo.astype(np.int64) * n + hi
    pos = np.clip(np.searchsorted(keys, k), 0, len(keys) - 1)
    return np.where(keys[pos] == k, order[pos], -1)


def _vangelder_cells(points, springs, cells, index):
    """Triangles for quads (van Gelder's formula is for triangles): a quad whose two
    diagonals are springs counts as the average of its two triangulations (weight 1/2
    each, returned as a weighted cell list); with one diagonal, that triangulation."""
    out = []
    for ctype, c in cells.items():
        if ctype != "quad":
            out.append((ctype, c))
            continue
        d02 = _lookup(index, c[:, 0], c[:, 2]) >= 0
        d13 = _lookup(index, c[:, 1], c[:, 3]) >= 0
        both, only02, only13, none = d02 & d13, d02 & ~d13, ~d02 & d13, ~d02 & ~d13
        t02 = lambda m: [c[m][:, [0, 1, 2]], c[m][:, [0, 2, 3]]]
        t13 = lambda m: [c[m][:, [0, 1, 3]], c[m][:, [1, 2, 3]]]
        for tris in (t02(only02), t13(only13)):
            out += [("triangle", t) for t in tris]
        for tris in (t02(both), t13(both)):
            out += [("triangle/2", t) for t in tris]
        if none.any():
            out.append(("quad", c[none]))
    return out


def vangelder(points, springs, cells, material) -> np.ndarray:
    if not cells:
        raise ModelError(
            "the van Gelder rule needs cells (a triangulation, a grid or a mesh)",
            field="model.stiffness",
        )
    d, L = spring_directions(points, springs)
    index = _spring_index(springs)
    acc = np.zeros(len(springs))
    for ctype, c in _vangelder_cells(points, springs, cells, index):
        weight = 0.5 if ctype == "triangle/2" else 1.0
        ctype = ctype.split("/")[0]
        meas = _cell_measure(points, c, ctype)
        Cc = element_stiffness(material, points[c].mean(axis=1))
        for i, j in element_pairs(ctype):
            s = _lookup(index, c[:, i], c[:, j])
            ok = s >= 0
            E = directional_modulus(Cc[ok], d[s[ok]])
            np.add.at(acc, s[ok], weight * E * meas[ok] / L[s[ok]] ** 2)
    return acc


# -- FEM element stiffness (for the Lloyd rule) --------------------------------------------

_REF = {
    "quad": np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float),
    "hexahedron": np.array(
        [
            [-1, -1, -1],
            [1, -1, -1],
            [1, 1, -1],
            [-1, 1, -1],
            [-1, -1, 1],
            [1, -1, 1],
            [1, 1, 1],
            [-1, 1, 1],
        ],
        float,
    ),
}


def _bmatrix(dN: np.ndarray) -> np.ndarray:
    """Strain-displacement matrices (m, voigt, nodes*dim) from gradients dN (m, nodes, dim)."""
    m, k, d = dN.shape
    if d == 2:
        B = np.zeros((m, 3, 2 * k))
        B[:, 0, 0::2] = dN[..., 0]
        B[:, 1, 1::2] = dN[..., 1]
        B[:, 2, 0::2] = dN[..., 1]
        B[:, 2, 1::2] = dN[..., 0]
        return B
    B = np.zeros((m, 6, 3 * k))
    for a in range(3):
        B[:, a, a::3] = dN[..., a]
    B[:, 3, 1::3], B[:, 3, 2::3] = dN[..., 2], dN[..., 1]
    B[:, 4, 0::3], B[:, 4, 2::3] = dN[..., 2], dN[..., 0]
    B[:, 5, 0::3], B[:, 5, 1::3] = dN[..., 1], dN[..., 0]
    return B


def fem_element_stiffness(
    points: np.ndarray, c: np.ndarray, ctype: str, C: np.ndarray
) -> np.ndarray:
    """Linear FEM element stiffness matrices (m, k*dim, k*dim) with dof = dim*local + comp."""
    p = points[c]
    if ctype in ("triangle", "tetra"):
        d = p.shape[2]
        T = p[:, 1:] - p[:, :1]  # (m, d, d) rows: edge vectors
        Tinv = np.linalg.inv(T)
        # (m, d, d+1): grad of N_i
        G = np.concatenate([-Tinv.sum(axis=2, keepdims=True), Tinv], axis=2)
        dN = np.transpose(G, (0, 2, 1))
        vol = np.abs(np.linalg.det(T)) / (2 if d == 2 else 6)
        B = _bmatrix(dN)
        return vol[:, None, None] * np.einsum("mvi,mvw,mwj->mij", B, C, B)
    ref = _REF[ctype]
    d = ref.shape[1]
    g = 1 / np.sqrt(3)
    K = 0
    for xi in np.array(np.meshgrid(*[[-g, g]] * d, indexing="ij")).reshape(d, -1).T:
        dNref = ref * np.prod(1 + ref * xi, axis=1, keepdims=True) / (1 + ref * xi) / 2**d  # (k, d)
        J = np.einsum("kd,mke->mde", dNref, p)  # (m, d_ref, d_phys)
        dN = np.einsum("med,kd->mke", np.linalg.inv(J), dNref)
        B = _bmatrix(dN)
        K = K + np.abs(np.linalg.det(J))[:, None, None] * np.einsum("mvi,mvw,mwj->mij", B, C, B)
    return K


def fit_element_springs(
    Ke: np.ndarray, points: np.ndarray, c: np.ndarray, pairs, nonneg: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Per element, k for the local ``pairs`` minimising ||Ke - sum k b b^T||_F (k >= 0
    with ``nonneg``). Returns k (m, len(pairs)) and the relative misfit (m,)."""
    m, k = c.shape
    d = points.shape[1]
    p = points[c]
    bs = np.zeros((m, len(pairs), k * d))
    for s, (i, j) in enumerate(pairs):
        v = p[:, j] - p[:, i]
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        bs[:, s, j * d : (j + 1) * d] = v
        bs[:, s, i * d : (i + 1) * d] = -v
    G = np.einsum("msi,mti->mst", bs, bs) ** 2
    h = np.einsum("msi,mij,msj->ms", bs, Ke, bs)
    # the minimum-norm least-squares solutions of all elements at once: lstsq's (rcond=None)
    # singular-value cut-off eps * size in a batched pseudo-inverse (a Python loop of lstsq
    # took 8 s on a 50k-tet mesh)
    out = (
        np.einsum("mst,mt->ms", np.linalg.pinv(G, rcond=np.finfo(float).eps * len(pairs)), h)
        if m
        else np.zeros((0, len(pairs)))
    )
    for e in np.flatnonzero(out.min(axis=1, initial=0.0) < 0) if nonneg else ():
        # nnls on the Frobenius problem written as a least-squares system
        A = np.stack([np.outer(b, b).ravel() for b in bs[e]], 1)
        out[e] = nnls(A, Ke[e].ravel())[0]
    model = np.einsum("ms,msi,msj->mij", out, bs, bs)
    mis = np.linalg.norm(Ke - model, axis=(1, 2)) / np.linalg.norm(Ke, axis=(1, 2))
    return out, mis


def lloyd(points, springs, cells, material) -> np.ndarray:
    if not cells:
        raise ModelError(
            "the Lloyd rule needs cells (a triangulation, a grid or a mesh)",
            field="model.stiffness",
        )
    index = _spring_index(springs)
    acc = np.zeros(len(springs))
    for ctype, c in cells.items():
        Cc = element_stiffness(material, points[c].mean(axis=1))
        Ke = fem_element_stiffness(points, c, ctype, Cc)
        pairs = element_pairs(ctype)
        ids = np.stack([_lookup(index, c[:, i], c[:, j]) for i, j in pairs], 1)
        # fit each distinct pattern of present springs separately
        present = ids >= 0
        for pattern in np.unique(present, axis=0):
            rows = np.all(present == pattern, axis=1)
            cols = np.flatnonzero(pattern)
            if len(cols) == 0:
                continue
            kfit, _ = fit_element_springs(Ke[rows], points, c[rows], [pairs[i] for i in cols])
            np.add.at(acc, ids[rows][:, cols].ravel(), kfit.ravel())
    # obtuse triangles give negative fitted constants (Lloyd et al. note it); the sum over
    # neighbouring cells usually compensates, the rest is floored at 1% of the median
    floor = 0.01 * np.median(acc[acc > 0]) if np.any(acc > 0) else 1.0
    return np.maximum(acc, floor)


def cauchy(points, springs, cells, material) -> np.ndarray:
    """Per cell, the constants whose Cauchy-Born stiffness (1/|T|) sum k L^2 a a^T best
    matches the material's Voigt C at the cell centre (least squares, minimum norm, k >= 0
    by NNLS only where needed), summed over the cells sharing a spring."""
    if not cells:
        raise ModelError(
            "the cauchy rule needs cells (a triangulation, a grid or a mesh)",
            field="model.stiffness",
        )
    index = _spring_index(springs)
    acc = np.zeros(len(springs))
    for ctype, c in cells.items():
        Cc = element_stiffness(material, points[c].mean(axis=1))
        vol = _cell_measure(points, c, ctype)
        pairs = element_pairs(ctype)
        ids = np.stack([_lookup(index, c[:, i], c[:, j]) for i, j in pairs], 1)
        present = ids >= 0
        for pattern in np.unique(present, axis=0):  # cells with the same springs present: one batch
            rows = np.flatnonzero(np.all(present == pattern, axis=1))
            cols = np.flatnonzero(pattern)
            if len(cols) == 0:
                continue
            v = (
                points[c[rows][:, [pairs[q][1] for q in cols]]]
                - points[c[rows][:, [pairs[q][0] for q in cols]]]
            )
            L = np.linalg.norm(v, axis=2)
            a = voigt_dyad((v / L[..., None]).reshape(-1, v.shape[2])).reshape(
                len(rows), len(cols), -1
            )
            M = (L[..., None, None] ** 2 * a[..., :, None] * a[..., None, :]).reshape(
                len(rows), len(cols), -1
            )
            M = M.transpose(0, 2, 1) / vol[rows][:, None, None]
            target = Cc[rows].reshape(len(rows), -1)
            k = np.einsum("mij,mj->mi", np.linalg.pinv(M), target)  # least squares, minimum norm
            for e in np.flatnonzero(k.min(axis=1) < 0):
                k[e] = nnls(M[e], target[e])[0]
            np.add.at(acc, ids[rows][:, cols].ravel(), k.ravel())
    floor = 0.01 * np.median(acc[acc > 0]) if np.any(acc > 0) else 1.0
    return np.maximum(acc, floor)


def learned(points, springs, cells, material) -> np.ndarray:
    """The fitted rule of harness/models/learned_rule.py: van Gelder's k times its correction."""
    return rule(points, springs, cells, material, base=vangelder(points, springs, cells, material))


def spring_constants(rule: str, points, springs, cells, material) -> np.ndarray:
    """k (e,) by the named rule."""
    if rule not in STIFFNESS_RULES:
        raise ModelError(
            f"unknown stiffness rule '{rule}'",
            field="model.stiffness",
            fix=f"one of {', '.join(RULES)}",
        )
    k = STIFFNESS_RULES.load(rule)(
        np.asarray(points, float), np.asarray(springs, int), cells or {}, material
    )
    if np.any(k <= 0):
        bad = np.flatnonzero(k <= 0)[:5]
        raise ModelError(
            f"rule '{rule}' gives zero stiffness to springs {bad.tolist()} (no cell contains them)",
            field="model.stiffness",
            fix="use the 'deussen' rule or a topology whose springs lie in cells",
        )
    return k
