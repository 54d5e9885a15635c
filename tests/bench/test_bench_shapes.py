"""bench shapes: its bodies mesh to the sizes it states, its digest sees every model
array and nothing else, and its busy machine is busy only while asked."""

import numpy as np
import pytest

from harness.bench import shapes as S
from harness.bench import shapes_bodies as B
from harness.registry import BENCHES


def test_registered():
    assert BENCHES.target("shapes") == "harness.bench.shapes"


def test_digest_sees_the_model_and_not_the_scores():
    data = {
        "particle_q": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
        "particle_mass": [1.0, 2.0],
        "spring_indices": [[0, 1]],
        "spring_stiffness": [3.0],
        "choice": "springs-prior1",
        "G_heldout_mean": 0.1,
        "opt_stop": "maxiter",
    }
    d = S.digest(data)
    assert S.digest({**data, "G_heldout_mean": 0.2, "opt_stop": "converged"}) == d
    assert S.digest({**data, "spring_stiffness": [np.nextafter(3.0, 4.0)]}) != d
    assert S.digest({**data, "choice": "rule"}) != d
    assert S.digest({**data, "node_volume_stiffness": [1.0]}) != d


def test_busy_spins_only_inside_the_block():
    import time

    with S.busy(2) as procs:
        time.sleep(0.2)
        assert len(procs) == 2 and all(p.poll() is None for p in procs)  # running
    assert all(p.poll() is not None for p in procs)  # and gone after


@pytest.mark.slow
def test_bodies_mesh_to_their_sizes(tmp_path):
    from harness.case.mesh_checks import check_mesh
    from harness.io.meshfile import read_mesh

    for shape in B.SHAPES:
        n = B.make_shape(shape, tmp_path / f"{shape.name}.vtu")
        m = read_mesh(tmp_path / f"{shape.name}.vtu")
        check_mesh(m, shape.name)
        assert 0.5 * shape.n_tets <= n <= 1.6 * shape.n_tets and len(m.cells["tetra"]) == n


def _signed_volumes(points, tets):
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])


def test_the_mirror_reflects_the_longest_axis_and_keeps_every_tet_positive(tmp_path):
    """The mirror of a jittered 3 x 1 x 1 box of tets: x reflected about the box's middle,
    y and z unchanged, every tet the same volume and still positive; twice is the identity."""
    import meshio
    import skfem

    box = skfem.MeshTet.init_tensor(
        *(np.linspace(0, s, n) for s, n in ((0.3, 7), (0.1, 3), (0.1, 3)))
    )
    points, tets = box.p.T.copy(), box.t.T.copy()
    rng = np.random.default_rng(0)
    points = points + rng.uniform(-0.004, 0.004, points.shape)
    tets = np.where(_signed_volumes(points, tets)[:, None] > 0, tets, tets[:, [1, 0, 2, 3]])
    meshio.write(tmp_path / "a.vtu", meshio.Mesh(points, [("tetra", tets)]))
    B.mirror(tmp_path / "a.vtu", tmp_path / "b.vtu")
    m = meshio.read(tmp_path / "b.vtu")
    lo, hi = points[:, 0].min(), points[:, 0].max()
    assert np.allclose(m.points[:, 0], lo + hi - points[:, 0])
    assert np.array_equal(m.points[:, 1:], points[:, 1:])
    v0, v1 = _signed_volumes(points, tets), _signed_volumes(m.points, m.cells_dict["tetra"])
    assert (v1 > 0).all() and np.allclose(v1, v0)
    B.mirror(tmp_path / "b.vtu", tmp_path / "c.vtu")
    assert np.allclose(meshio.read(tmp_path / "c.vtu").points, points)


def test_the_mirror_columns_and_the_verdict():
    row = S._mirrored(
        {"G_heldout_mean": 0.2, "best_rule_heldout": {"rule": "uniform", "G_heldout_mean": 0.16}}
    )
    assert row["best_rule_mirror"] == "uniform" and row["ratio_mirror"] == pytest.approx(1.25)
    assert np.isnan(S._mirrored({})["ratio_mirror"])
    import pandas as pd

    df = pd.DataFrame(
        dict(
            ratio=[1.2, 1.0],
            reference_error_heldout=[0.005, 0.02],
            same_export=[True, True],
            ratio_mirror=[1.04, 1.1],
        )
    )
    assert "(worst 1.2; mirrored: 1)" in S.verdict(df)
