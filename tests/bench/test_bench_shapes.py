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
