"""SMS natural frequencies approach the FEM's as an isotropic lattice is refined
(independent truth: the continuum modal problem solved by the reference)."""

import numpy as np
import pytest

import reference
from harness.case.reader import load_case
from harness.mechanics.modal import frequencies
from harness.models.sms import build_network

CASE = """
name = "modal-lattice"
dim = 2
[body]
shape = "rectangle"
size = [4.0, 4.0]
[material]
E = 1000.0
nu = 0.3333333333333333
density = 1.0
[loads]
set = "basic2d"
[reference]
divisions = 8
max_refine = 0
[model]
kind = "sms"
placement = "grid"
grid = [{n}, {n}]
structure = "structure1"
masses = "moments-nonneg"
stiffness = "cauchy"
"""


@pytest.mark.slow
def test_lattice_frequencies_converge_to_fem(tmp_path):
    errors = []
    fem = None
    for n in (5, 17):
        p = tmp_path / f"n{n}.toml"
        p.write_text(CASE.format(n=n))
        case = load_case(p)
        if fem is None:
            fem = reference.solve(case, cache=False).frequencies(4, load="stretch-x")
        f = frequencies(build_network(case), case, 4, load="stretch-x")
        errors.append(np.abs(f / fem - 1).max())
    assert errors[1] < errors[0] / 2
    assert errors[1] < 0.05
