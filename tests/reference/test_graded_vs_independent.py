"""The product's 3-D reference against the independent solve of tests/independent/
(own Kronecker Q2 assembly on a symmetric quarter, own grading with the scored points on
nodes, own extrapolation): the box shear at the 4 x 4 x 4 points a grid model is scored at.

Measured (results/bench/reference.csv): uniform P2 tets 1.9 % at 6.6k dofs; graded Q2 +
extrapolation 4.4e-4 at 14.7k dofs (levels 2, 3, 4), 2.1e-4 at 27.8k and 47k. The issue's
target (1e-4) is not met yet; these tests hold what is: a true error below 1e-3 from
three small levels, and an estimate that bounds the true error at every point."""

import dataclasses
import textwrap

import numpy as np
import pytest

import reference
from harness.case.reader import load_case
from tests.independent import extrapolated_shear

E, NU, S = 1000.0, 0.3, 1.0


def shear_case(tmp_path, size, max_refine):
    p = tmp_path / "shear.toml"
    p.write_text(
        textwrap.dedent(f"""
        name = "shear"
        dim = 3
        [body]
        shape = "box"
        size = {list(size)}
        [material]
        E = {E}
        nu = {NU}
        [[loads.case]]
        name = "shear-xz"
        [[loads.case.constraint]]
        part = "z0"
        components = "all"
        [[loads.case.traction]]
        part = "z1"
        vector = [{S}, 0.0, 0.0]
        [reference]
        max_refine = {max_refine}
        """)
    )
    return load_case(p)


@pytest.mark.slow
@pytest.mark.parametrize("size", [(3.0, 3.0, 3.0), (1.5, 3.0, 2.25)])
def test_graded_reference_against_the_independent_solve(tmp_path, size):
    pts = np.stack(np.meshgrid(*[np.linspace(0, s, 4) for s in size], indexing="ij"), -1).reshape(
        -1, 3
    )
    truth, change, order = extrapolated_shear(size, E, NU, S, pts, levels=(8, 12, 16), knot=0.75)
    assert change < 2e-5 and 2.0 < order < 3.5  # the truth is converged
    scale = np.linalg.norm(truth, axis=1).max()
    case = shear_case(tmp_path, size, max_refine=2)
    assert case.reference.method == "graded"
    sol = reference.solve(case, cache=False)
    u = sol.displacement(pts, "shear-xz")
    err = np.linalg.norm(u - truth, axis=1)
    est = sol.error_estimate(pts, "shear-xz")
    assert err.max() < 1e-3 * scale, err.max() / scale
    assert np.all(est >= err), (err / scale, est / scale)  # the estimate bounds the error
    assert est.max() < 10 * max(err.max(), 1e-4 * scale)  # and is not vacuous
    assert sol.error_estimate["shear-xz"] >= err.max() / scale * 0.5
    # uniform P2 tets are much worse at similar cost
    base = shear_case(tmp_path, size, 0)
    tets = dataclasses.replace(
        base,
        reference=dataclasses.replace(base.reference, cell="tet", divisions=6, method="refine"),
    )
    tet = reference.solve(tets, cache=False)
    err_tet = np.linalg.norm(tet.displacement(pts, "shear-xz") - truth, axis=1).max()
    assert err_tet > 5 * err.max()
