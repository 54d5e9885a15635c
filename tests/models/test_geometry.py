"""Bodies, placement, Lloyd iteration and topology (independent truths: exact areas and
moments, counting, Deussen Fig. 2's trend)."""

import numpy as np
import pytest

from harness.errors import ModelError
from harness.geometry import box, grid_points, lloyd, polygon, random_points, rectangle
from harness.geometry.placement import voronoi_cells_2d
from harness.models.masses import polygon_moments
from harness.models.topology import delaunay, grid_structure, mesh_edges, simplex_quality

L_SHAPE = [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]


def test_grid_points_order_and_rectangular_cells():
    p = grid_points([0, 0], [2, 1], (5, 3))
    assert p.shape == (15, 2)
    assert np.allclose(p[1] - p[0], [0.5, 0])  # x fastest
    assert np.allclose(p[5] - p[0], [0, 0.5])
    with pytest.raises(ModelError):
        grid_points([0, 0], [1, 1], (1, 3))


@pytest.mark.parametrize("body", [rectangle([0, 0], [1, 1]), polygon(L_SHAPE)])
def test_random_points_include_vertices_and_boundary(body):
    p = random_points(body, 40, seed=3)
    assert p.shape == (40, 2)
    assert body.contains(p).all()
    for v in body.vertices:
        assert np.any(np.all(np.isclose(p, v), axis=1))
    assert body.on_boundary(p).sum() > len(body.vertices)
    assert np.array_equal(p, random_points(body, 40, seed=3))
    assert not np.array_equal(p, random_points(body, 40, seed=4))


def test_random_points_box_on_faces_and_corners():
    b = box([0, 0, 0], [1, 2, 1])
    p = random_points(b, 80, seed=1)
    assert p.shape == (80, 3) and b.contains(p).all()
    for c in b.corners:
        assert np.any(np.all(np.isclose(p, c), axis=1))
    for axis in range(3):
        for side in (b.lo, b.hi):
            assert np.sum(np.isclose(p[:, axis], side[axis])) >= 4


def test_voronoi_cells_exact_area_and_first_moments_nonconvex():
    body = polygon(L_SHAPE)
    p = random_points(body, 30, seed=0)
    areas, cents = voronoi_cells_2d(p, body)
    m = polygon_moments(body.vertices)  # independent: Green's theorem on the polygon
    assert np.isclose(areas.sum(), m[0], rtol=1e-12)
    assert np.allclose((areas[:, None] * cents).sum(0), m[1:3], rtol=1e-12)
    assert (areas > 0).all()


@pytest.mark.parametrize("body", [rectangle([0, 0], [1, 1]), polygon(L_SHAPE)])
def test_lloyd_reduces_both_standard_deviations(body):
    p = random_points(body, 40, seed=5)
    res = lloyd(body, p, 15)
    assert len(res.std_distance) == 16 and len(res.std_size) == 16
    assert res.std_distance[-1] < 0.8 * res.std_distance[0]
    assert res.std_size[-1] < 0.8 * res.std_size[0]
    # vertices fixed, boundary points still on the boundary
    on0 = body.on_boundary(p)
    assert body.on_boundary(res.points[on0]).all()
    for v in body.vertices:
        assert np.any(np.all(np.isclose(res.points, v), axis=1))
    assert body.contains(res.points).all()
    assert np.isclose(res.sizes.sum(), body.volume, rtol=1e-12)


def test_lloyd_3d_sampled_reduces_spread():
    b = box([0, 0, 0], [1, 1, 1])
    p = random_points(b, 60, seed=2)
    res = lloyd(b, p, 6, seed=0, samples_per_point=400)
    assert res.std_distance[-1] < 0.85 * res.std_distance[0]
    assert res.std_size[-1] < 0.85 * res.std_size[0]
    on = b.on_boundary(p)
    assert b.on_boundary(res.points[on]).all()


def test_grid_structures_counts_and_groups():
    t = grid_structure((5, 5), "structure1")
    assert len(t.springs) == 20 + 20 + 32
    assert t.group_names == ("horizontal", "vertical", "diagonal")
    assert np.bincount(t.groups).tolist() == [20, 20, 32]
    assert len(grid_structure((5, 5), "edges+diagonal").springs) == 56
    assert len(grid_structure((5, 5), "edges+diagonals+second").springs) == 72 + 30
    t3 = grid_structure((3, 3, 3), "edges+face+body")
    assert np.bincount(t3.groups).tolist() == [18, 18, 18, 24, 24, 24, 32]
    assert len(np.unique(t3.springs, axis=0)) == len(t3.springs)
    with pytest.raises(ModelError, match="structure"):
        grid_structure((3, 3), "nonsense")


def test_grid_spring_lengths_match_names():
    p = grid_points([0, 0], [4, 2], (5, 3))
    t = grid_structure((5, 3), "structure1")
    d = p[t.springs[:, 1]] - p[t.springs[:, 0]]
    h = d[t.groups == 0]
    v = d[t.groups == 1]
    assert np.allclose(np.abs(h), [1, 0]) and np.allclose(np.abs(v), [0, 1])
    assert np.allclose(np.abs(d[t.groups == 2]), [1, 1])


def test_delaunay_nonconvex_filter_and_slivers():
    body = polygon(L_SHAPE)
    p = random_points(body, 50, seed=1)
    t = delaunay(p, body)
    mid = (p[t.springs[:, 0]] + p[t.springs[:, 1]]) / 2
    assert body.contains(mid).all()  # no spring across the notch
    assert len(np.unique(t.springs)) == len(p)
    # a cubic grid is cospherical: flat tetrahedra are dropped
    g = grid_points([0, 0, 0], [1, 1, 1], (3, 3, 3))
    t3 = delaunay(g)
    assert simplex_quality(g, t3.cells["tetra"]).min() >= 1e-3


def test_mesh_edges_hex_adds_diagonals():
    hexa = np.arange(8)[None]
    assert len(mesh_edges({"hexahedron": hexa}).springs) == 28
    assert len(mesh_edges({"quad": np.arange(4)[None]}).springs) == 6
    assert len(mesh_edges({"triangle": np.array([[0, 1, 2], [1, 2, 3]])}).springs) == 5
