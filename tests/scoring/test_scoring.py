"""G criteria (Deussen eq. 12 / Section 5.4; docs/design.md, "The G criteria") on hand-computed
cases."""

import numpy as np
import pytest

from harness.case.loadsets import basic2d, stretch_closed_form
from harness.case.reader import Body, Case, Material
from harness.geometry import grid_points
from harness.mechanics.homogenize import boundary_share
from harness.models.sms import make_network
from harness.models.topology import grid_structure
from harness.scoring import g_arrays, node_weights, score


def test_g_hand_computed_four_nodes():
    # classes: inner, border, corner, border; weights 1:3:15 -> w = 1, 3, 15, 3
    classes = np.array([0, 1, 2, 1])
    u_ref = np.array([[[1.0, 0], [0, 2], [1, 1], [2, 2]]])
    u = np.array([[[0.0, 0], [0, 0], [0, 0], [2, 2]]])  # errors |d|^2 = 1, 4, 2, 0
    r = g_arrays(u_ref, u, classes, (1, 3, 15), ["a"])
    assert r.G == pytest.approx(np.sqrt(1 * 1 + 3 * 4 + 15 * 2 + 3 * 0))  # sqrt(43)
    assert r.G_s == pytest.approx(np.sqrt(7))
    # normaliser: sum w |u_ref|^2 = 1*1 + 3*4 + 15*2 + 3*8 = 67
    assert r.G_norm == pytest.approx(np.sqrt(43 / 67))
    assert r.per_load["a"] == pytest.approx(np.sqrt(43))
    assert node_weights(classes, (1, 3, 15)).tolist() == [1, 3, 15, 3]


def test_g_adds_loads_in_quadrature_and_is_zero_for_exact():
    rng = np.random.default_rng(0)
    u_ref = rng.normal(size=(3, 6, 2))
    u = rng.normal(size=(3, 6, 2))
    classes = np.array([0, 0, 1, 1, 2, 2])
    r = g_arrays(u_ref, u, classes, (1, 6, 18), ["p", "q", "r"])
    assert r.G**2 == pytest.approx(sum(v**2 for v in r.per_load.values()))
    assert g_arrays(u_ref, u_ref, classes, (1, 6, 18)).G == 0
    rows = r.rows()
    assert [x["load"] for x in rows] == ["p", "q", "r", "total"]
    with pytest.raises(ValueError):
        g_arrays(u_ref, u[:, :5], classes, (1, 1, 1))


class _ClosedForm:
    """A stand-in reference: the plane-stress closed form of the stretches (docs/design.md,
    "Load sets for boxes")."""

    def __init__(self, case):
        self.case = case

    def displacement(self, points, load):
        lc = next(l for l in self.case.loads if l.name == load)
        return stretch_closed_form(
            lc, points, self.case.material.E, self.case.material.nu, self.case.body.bbox()[0]
        )


def test_score_zero_for_the_exact_lattice_on_stretches():
    """A nu = 1/3 square lattice with the Cauchy-Born constants (k_e = 3E/4, k_d = 3E/8)
    assembled cell-wise reproduces the stretch closed form exactly: G = 0 on stretches,
    and the weights follow the node classes."""
    E, n = 2.0, 9
    case = Case(
        path=None,
        name="t",
        dim=2,
        body=Body("rectangle", (0.0, 0.0), (8.0, 8.0)),
        material=Material(E, 1 / 3),
        loads=basic2d(0.01)[:2],
        reference=None,
    )
    p = grid_points([0, 0], [8, 8], (n, n))
    top = grid_structure((n, n), "structure1")
    k = np.array([0.75 * E, 0.75 * E, 0.375 * E])[top.groups] * boundary_share(
        p, top.springs, (0, 0), (8, 8)
    )
    net = make_network(p, top.springs, k, bbox=((0, 0), (8, 8)))
    r = score(net, case, _ClosedForm(case), weights=(1, 3, 15))
    assert r.G < 1e-12 and r.G_norm < 1e-9
    net2 = net.with_k(net.k * 2)  # twice as stiff: u halves, error = u_ref / 2
    r2 = score(net2, case, _ClosedForm(case), weights=(1, 3, 15))
    assert r2.G_norm == pytest.approx(0.5, rel=1e-9)
    assert r2.G_s == pytest.approx(
        0.5
        * np.sqrt(
            sum(
                np.sum(_ClosedForm(case).displacement(p, l) ** 2)
                for l in ("stretch-x", "stretch-y")
            )
        ),
        rel=1e-9,
    )
