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
    a, e = np.broadcast_arrays(np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(e, float)))
    return np.stack([np.cos(a) * np.cos(e), np.sin(e), np.sin(a) * np.cos(e)], axis=1)


def named_field_angles(name: str, centroids: np.ndarray, seed: int = 0):
    """(azimuth, elevation) per element for a named field of the original program."""
    n = len(centroids)
    if name == "vertical":
        return np.zeros(n), np.full(n, np.pi / 2)
    if name == "horizontal":
        return np.full(n, np.pi / 2), np.zeros(n)
    if name == "diagonal":
        return np.zeros(n), np.full(n, np.pi / 4)
    if name == "random":
        rng = np.random.default_rng(seed)
        return rng.uniform(0, 2 * np.pi, n), rng.uniform(-np.pi / 2, np.pi / 2, n)
    raise NotImplementedError(f"fibre field '{name}' is not implemented yet")


def fibre_directions(centroids: np.ndarray, *, direction=None, azimuth_deg=None,
                     elevation_deg=None, field=None, seed: int = 0) -> np.ndarray:
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
        return azimuth_elevation(*named_field_angles(field, centroids, seed))
    a = np.deg2rad(azimuth_deg or 0.0)
    if dim == 2:
        return np.tile([np.cos(a), np.sin(a)], (n, 1))
    e = np.deg2rad(elevation_deg or 0.0)
    return np.tile(azimuth_elevation(a, e)[0], (n, 1))
