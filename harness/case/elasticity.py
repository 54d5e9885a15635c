"""Constitutive matrices in Voigt notation, shared by the reference and the models.

3-D order (xx, yy, zz, yz, xz, xy) with engineering shear strains; 2-D order
(xx, yy, xy). A transversely isotropic material has its fibre (the symmetry axis)
along local x; ``rotate`` turns it onto any direction. Plane stress reduces the
3-D compliance, plane strain the 3-D stiffness, so both hold for anisotropy too.
"""

from __future__ import annotations

import numpy as np

from harness.case.case import Material
from harness.case.fibres import fibre_directions

_VOIGT = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]


def isotropic_compliance(E: float, nu: float) -> np.ndarray:
    return transversely_isotropic_compliance(E, E, nu, nu, E / (2 * (1 + nu)))


def transversely_isotropic_compliance(E_L, E_T, nu_LT, nu_TT, G_LT) -> np.ndarray:
    """6x6 compliance, fibre along x: nu_LT = -eps_T/eps_L under stress along the fibre."""
    S = np.zeros((6, 6))
    S[0, 0] = 1 / E_L
    S[1, 1] = S[2, 2] = 1 / E_T
    S[0, 1] = S[1, 0] = S[0, 2] = S[2, 0] = -nu_LT / E_L
    S[1, 2] = S[2, 1] = -nu_TT / E_T
    S[3, 3] = 2 * (1 + nu_TT) / E_T
    S[4, 4] = S[5, 5] = 1 / G_LT
    return S


def voigt_to_tensor(C: np.ndarray) -> np.ndarray:
    """6x6 stiffness (engineering shear) -> 3x3x3x3 tensor."""
    T = np.zeros((3, 3, 3, 3))
    for I, (i, j) in enumerate(_VOIGT):
        for J, (k, l) in enumerate(_VOIGT):
            for a, b in ((i, j), (j, i)):
                for c, d in ((k, l), (l, k)):
                    T[a, b, c, d] = C[I, J]
    return T


def tensor_to_voigt(T: np.ndarray) -> np.ndarray:
    """(..., 3,3,3,3) -> (..., 6, 6)."""
    idx = np.array(_VOIGT)
    return T[..., idx[:, 0][:, None], idx[:, 1][:, None], idx[:, 0][None, :], idx[:, 1][None, :]]


def frame(d: np.ndarray) -> np.ndarray:
    """Orthonormal frames (n, 3, 3) whose first row is the unit vector d (n, 3)."""
    d = np.atleast_2d(np.asarray(d, float))
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    helper = np.where(np.abs(d[:, [0]]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e2 = np.cross(d, helper)
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    e3 = np.cross(d, e2)
    return np.stack([d, e2, e3], axis=1)


def rotate(C: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Stiffness C (6x6, symmetry axis along x) turned so that x maps to each direction.
    directions (n, 2|3) -> (n, 6, 6)."""
    d = np.atleast_2d(np.asarray(directions, float))
    if d.shape[1] == 2:
        d = np.hstack([d, np.zeros((len(d), 1))])
    Q = frame(d)  # rows: local axes in global coordinates
    T = voigt_to_tensor(C)
    Tg = np.einsum("nai,nbj,nck,ndl,abcd->nijkl", Q, Q, Q, Q, T, optimize=True)
    return tensor_to_voigt(Tg)


def plane(C: np.ndarray, mode: str) -> np.ndarray:
    """3-D stiffness (..., 6, 6) -> 2-D (..., 3, 3) for plane 'stress' or 'strain'."""
    keep = [0, 1, 5]
    if mode == "strain":
        return C[..., keep, :][..., :, keep]
    S = np.linalg.inv(C)
    return np.linalg.inv(S[..., keep, :][..., :, keep])


def lame(E: float, nu: float) -> tuple[float, float]:
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def isotropic(E: float, nu: float, density: float = 1.0, plane: str = "stress") -> Material:
    """The isotropic :class:`Material` of (E, nu, density); ValueError unless E > 0 and
    -1 < nu < 0.5 (where both Lame constants are finite and mu > 0)."""
    if not (np.isfinite(E) and E > 0 and -1.0 < nu < 0.5):
        raise ValueError(f"E = {E!r}, nu = {nu!r} is no isotropic material (E > 0, -1 < nu < 0.5)")
    return Material(float(E), float(nu), float(density), plane)


def in_region(region, points: np.ndarray) -> np.ndarray:
    """Mask of the points (n, dim) inside a ``harness.case.reader.Region`` box."""
    return np.all(
        (points >= np.asarray(region.lo) - 1e-12) & (points <= np.asarray(region.hi) + 1e-12),
        axis=1,
    )


def densities(material, points: np.ndarray) -> np.ndarray:
    """Density at points (n, dim), e.g. element centroids; a region with its own density
    overrides the material's."""
    points = np.asarray(points, float)
    rho = np.full(len(points), float(material.density))
    for r in material.regions:
        if r.density is not None:
            rho[in_region(r, points)] = r.density
    return rho


def element_stiffness(material, centroids: np.ndarray) -> np.ndarray:
    """Voigt stiffness per element (n, 3, 3) in 2-D or (n, 6, 6) in 3-D for a
    ``harness.case.reader.Material`` (isotropic, fibre, regions) at element centroids (n, dim).

    A region overrides E (and nu) of the isotropic part; with a fibre, a region scales
    every modulus of the fibre material by E_region / E.
    """
    centroids = np.asarray(centroids, float)
    n, dim = centroids.shape
    scale = np.ones(n)
    nu = np.full(n, material.nu)
    for r in material.regions:
        inside = in_region(r, centroids)
        scale[inside] = r.E / material.E
        if r.nu is not None:
            nu[inside] = r.nu
    f = material.fibre
    if f is None:
        out = np.empty((n, 6, 6))
        for val in np.unique(nu):
            out[nu == val] = np.linalg.inv(isotropic_compliance(material.E, val))
    else:
        C = np.linalg.inv(
            transversely_isotropic_compliance(
                f.E_fibre, f.E_cross, f.nu_fibre, f.nu_cross, f.G_fibre
            )
        )
        d = fibre_directions(
            centroids,
            direction=f.direction,
            azimuth_deg=f.azimuth_deg,
            elevation_deg=f.elevation_deg,
            field=f.field,
            seed=f.seed,
        )
        out = rotate(C, d)
    out = out * scale[:, None, None]
    return plane(out, material.plane) if dim == 2 else out
