"""The adaptive levels fill up to the dof cap (reference/adaptive/adapt.py ``_within_cap``):
where Dörfler's set would pass the cap, the elements with the largest indicators that fit
are refined, the most of them that fit; a level that cannot grow by GROWTH_MIN is none."""

import numpy as np
from skfem import MeshTet

from reference.adaptive.adapt import _within_cap
from reference.adaptive.wide import n_dofs


def test_the_largest_prefix_of_the_marked_elements_that_fits_is_refined():
    mesh = MeshTet.init_tensor(*[np.linspace(0, 1, 5)] * 3)
    rng = np.random.default_rng(0)
    total = rng.random(mesh.t.shape[1])
    marked = np.flatnonzero(total > 0.3)
    order = marked[np.argsort(-total[marked], kind="stable")]
    every = n_dofs(mesh.refined(marked), "P2")
    cap = (n_dofs(mesh, "P2") + every) // 2
    got = _within_cap(mesh, marked, total, cap, "P2")
    assert n_dofs(got, "P2") <= cap
    # the same mesh as refining the m largest, and m + 1 would pass the cap
    m = next(m for m in range(len(order), 0, -1) if n_dofs(mesh.refined(order[:m]), "P2") <= cap)
    np.testing.assert_array_equal(got.t, mesh.refined(order[:m]).t)
    assert n_dofs(mesh.refined(order[: m + 1]), "P2") > cap
    assert _within_cap(mesh, marked, total, n_dofs(mesh, "P2"), "P2") is None  # no room
