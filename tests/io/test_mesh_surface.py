"""harness.io.meshfile's boundary facets against an independent count (a facet is on the
boundary when exactly one cell has it, counted here with a Python dict), and
mesh_surface's cache: the same arrays while the file is unchanged, read-only, and a
new reading once the file changes."""

from __future__ import annotations

import os

import meshio
import numpy as np
import pytest
from scipy.spatial import Delaunay

from harness.io import meshfile


def _cloud(n=300, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 1, (n, 3))
    return p, Delaunay(p).simplices


def _by_dict(cells):
    count, first = {}, {}
    for c in cells:
        for f in meshfile.FACETS["tetra"]:
            face = tuple(c[list(f)])
            key = tuple(sorted(face))
            count[key] = count.get(key, 0) + 1
            first.setdefault(key, face)
    return {first[k] for k, v in count.items() if v == 1}


def test_boundary_facets_match_a_dict_count():
    p, t = _cloud()
    (faces,), (inside,) = meshfile.boundary_facets({"tetra": t}, p)
    assert {tuple(f) for f in faces} == _by_dict(t)
    assert len(faces) == len(_by_dict(t))
    # each facet's inside point is the centroid of a cell that has all its vertices
    for f, c in zip(faces[:50], inside[:50]):
        owners = [cell for cell in t if set(f) <= set(cell)]
        assert len(owners) == 1 and np.allclose(p[owners[0]].mean(axis=0), c)


def test_packed_keys_and_row_unique_agree():
    rng = np.random.default_rng(3)
    rows = rng.integers(0, 6, (400, 3))
    _, first, count = np.unique(rows, axis=0, return_index=True, return_counts=True)
    np.testing.assert_array_equal(meshfile._once(rows), np.sort(first[count == 1]))
    big = rows.astype(np.int64) * (2**40)  # too large to pack: the row path
    np.testing.assert_array_equal(meshfile._once(big), np.sort(first[count == 1]))


def test_mesh_surface_is_cached_read_only_and_renewed(tmp_path):
    p, t = _cloud()
    path = tmp_path / "m.vtu"
    meshio.write(path, meshio.Mesh(p, [("tetra", t)]))
    a = meshfile.mesh_surface(path)
    assert meshfile.mesh_surface(path) is a
    points, facets, inside = a
    np.testing.assert_allclose(points, p)
    assert {tuple(f) for f in facets[0]} == _by_dict(t)
    with pytest.raises(ValueError):
        points[0, 0] = 1.0
    p2, t2 = _cloud(200, seed=1)
    meshio.write(path, meshio.Mesh(p2, [("tetra", t2)]))
    st = path.stat()
    # a new version even within one tick
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    b = meshfile.mesh_surface(path)
    assert b is not a and {tuple(f) for f in b[1][0]} == _by_dict(t2)


def test_mesh_points_cached_and_renewed(tmp_path):
    p, t = _cloud()
    path = tmp_path / "m.vtu"
    meshio.write(path, meshio.Mesh(p, [("tetra", t)]))
    a = meshfile.mesh_points(path)
    assert meshfile.mesh_points(path) is a and not a.flags.writeable
    np.testing.assert_allclose(a, p)
    meshio.write(path, meshio.Mesh(2 * p, [("tetra", t)]))
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    np.testing.assert_allclose(meshfile.mesh_points(path), 2 * p)


def test_missing_file_is_the_readers_one_line_error(tmp_path):
    from harness.errors import SpringbenchError

    for f in (meshfile.mesh_points, meshfile.mesh_surface):
        with pytest.raises(SpringbenchError, match="no such mesh file"):
            f(tmp_path / "nope.vtu")
