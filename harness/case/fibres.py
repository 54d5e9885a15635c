"""Fibre directions: constant, by azimuth/elevation, or a named field per element.

The convention is Bourguignon & Cani's program (shared/reference-data README):
f1 = (cos a cos e, sin e, sin a cos e), so a = 0, e = pi/2 is +y (vertical). In 2-D the
azimuth is the in-plane angle from +x. Fields are evaluated at element centroids.
"""

from __future__ import annotations

import numpy as np

NAMED_FIELDS = ("vertical", "horizontal", "diagonal", "hemicircular", "helicoidal", "random")


def azimuth_elevation(a: np.ndarray | float, e: np.ndarray | float) -> np.ndarray:
    """Unit vectors (n, 3) for azimuth a and elevation e in radians."""
    a, e = np.broadcast_arrays(
        np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(e, float))
    )
    return np.stack([np.cos(a) * np.cos(e), np.sin(e), np.sin(a) * np.cos(e)], axis=1)


def named_field_angles(name: str, centroids: np.ndarray, seed: int = 0, origin=None):
    """(azimuth, elevation) per element for a named field of the original program.

    vertical (its EXAMPLE_1: a = e = pi/2, f1 = +y), horizontal (a = pi/2, e = 0: +z),
    diagonal (a = pi/2, e = pi/4), random (a uniform in [0, pi), e in [-pi/2, pi/2),
    seeded), and the two fields set from each element's barycentre g (Fig. 6):

    - hemicircular (EXAMPLE_4, a "C" in the y-z plane): O = (g_x, O_y, O_z) with
      (O_y, O_z) = ``origin`` or (2.5, 3.0) (cube_353's back face); v = normalise(OP x (-1,0,0));
      a = pi/2, e = atan(v_y / v_z);
    - helicoidal (EXAMPLE_5, around the vertical axis through (O_x, O_z) = ``origin`` or
      (1.5, 1.5)): v = normalise(OP x (0,1,0)), a = atan(v_z / v_x), e = pi/4 where
      g_z <= O_z else -pi/4.
    """
    g = np.asarray(centroids, float)
    n = len(g)
    if name == "vertical":
        return np.full(n, np.pi / 2), np.full(n, np.pi / 2)
    if name == "horizontal":
        return np.full(n, np.pi / 2), np.zeros(n)
    if name == "diagonal":
        return np.full(n, np.pi / 2), np.full(n, np.pi / 4)
    if name == "random":
        rng = np.random.default_rng(seed)
        return rng.uniform(0, np.pi, n), rng.uniform(-np.pi / 2, np.pi / 2, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        if name == "hemicircular":
            oy, oz = (2.5, 3.0) if origin is None else origin
            OP = np.stack([np.zeros(n), g[:, 1] - oy, g[:, 2] - oz], axis=1)
            v = np.cross(OP, [-1.0, 0.0, 0.0])
            v = v / np.linalg.norm(v, axis=1, keepdims=True)
            return np.full(n, np.pi / 2), np.arctan(v[:, 1] / v[:, 2])
        if name == "helicoidal":
            ox, oz = (1.5, 1.5) if origin is None else origin
            OP = np.stack([g[:, 0] - ox, np.zeros(n), g[:, 2] - oz], axis=1)
            v = np.cross(OP, [0.0, 1.0, 0.0])
            v = v / np.linalg.norm(v, axis=1, keepdims=True)
            return np.arctan(v[:, 2] / v[:, 0]), np.where(g[:, 2] <= oz, np.pi / 4, -np.pi / 4)
    raise ValueError(f"unknown fibre field '{name}' (known: {', '.join(NAMED_FIELDS)})")


def fibre_directions(
    centroids: np.ndarray,
    *,
    direction=None,
    azimuth_deg=None,
    elevation_deg=None,
    field=None,
    seed: int = 0,
    origin=None,
) -> np.ndarray:
    """Unit fibre direction per element, shape (n, dim), dim taken from ``centroids``."""
    centroids = np.asarray(centroids, float)
    n, dim = centroids.shape
    if direction is not None:
        d = np.asarray(direction, float)
        d = d / np.linalg.norm(d)
        return np.tile(d, (n, 1))
    if field is not None:
        if dim == 2:
            raise NotImplementedError("named fibre fields are 3-D")
        return azimuth_elevation(*named_field_angles(field, centroids, seed, origin))
    a = np.deg2rad(azimuth_deg or 0.0)
    if dim == 2:
        return np.tile([np.cos(a), np.sin(a)], (n, 1))
    e = np.deg2rad(elevation_deg or 0.0)
    return np.tile(azimuth_elevation(a, e)[0], (n, 1))
