"""``[model] classes`` in the sms stage: the classes share nodes, masses, loads
and reference; the ``springs`` class gives the rows of the same case without classes, bit
for bit; ``k_spread`` is max/median of the fitted row's stored constants; ``dt_stable`` of
the P1 row is 2 / omega_max of a dense eigen-solve written here (scikit-fem's P1 K on the
same triangles, the model's masses)."""

import textwrap

import numpy as np
import pytest
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

from harness.case.reader import load_case
from harness.export.vtu import read_vtu
from harness.models.sms import model_spec
from harness.registry import MODEL_CLASSES
from harness.stages import StageContext
from harness.stages import sms as stage

E, NU = 1000.0, 0.4

TEXT = textwrap.dedent(f"""
    name = "classes"
    dim = 2
    [body]
    shape = "rectangle"
    size = [2.0, 1.0]
    [material]
    E = {E}
    nu = {NU}
    [loads]
    set = "homogeneous2d"
    heldout = ["tip"]
    [[loads.case]]
    name = "tip"
    [[loads.case.constraint]]
    part = "x0"
    components = "all"
    [[loads.case.traction]]
    part = "x1"
    vector = [0.0, -1.0]
    [reference]
    divisions = 4
    max_refine = 1
    modes = 2
    [model]
    kind = "sms"
    placement = "grid"
    grid = [5, 3]
    masses = "voronoi"
    stiffness = ["lloyd"]
    {{classes}}
    [optimizer]
    method = "lbfgs"
    options = {{{{ maxiter = 15 }}}}
    """)


def _case(tmp_path, name, classes):
    p = tmp_path / f"{name}.toml"
    p.write_text(TEXT.format(classes=classes))
    return load_case(p)


def test_classes_share_the_model_and_springs_equals_the_plain_case(tmp_path):
    case = _case(tmp_path, "c", 'classes = ["springs", "springs+volume-shared", "p1"]')
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    plain = stage.run(_case(tmp_path, "p", ""), StageContext(out_dir=tmp_path / "plain"))
    by = {}
    for r in rows:
        by.setdefault(r["model_class"], []).append(r)
    # p1: the plain row and its fit of a material per element (the case runs an optimiser)
    assert [len(by[c]) for c in ("springs", "springs+volume-shared", "p1")] == [2, 2, 2]
    assert {r["n_nodes"] for r in rows} == {15} and {r["nu"] for r in rows} == {NU}
    for a, b in zip(by["springs"], plain):
        assert a["G_norm_final"] == b["G_norm_final"] and a["G_heldout"] == b["G_heldout"]
    # the volume term is there (a different model) and the P1 row has no constants
    assert by["springs+volume-shared"][0]["G_norm_final"] != by["springs"][0]["G_norm_final"]
    p1 = by["p1"][0]
    assert p1["optimizer"] == "none" and np.isnan(p1["k_spread"]) and "cauchy_misfit" not in p1
    # k_spread of the fitted springs: from the stored constants
    net, _ = read_vtu(tmp_path / "out" / "springs" / "model-lloyd-lbfgs.vtu")
    assert by["springs"][1]["k_spread"] == pytest.approx(net.k.max() / np.median(net.k), rel=1e-12)
    # dt_stable of P1: dense eigen-solve of M^-1 K with scikit-fem's plane-stress P1 stiffness
    cls = MODEL_CLASSES.load("p1")
    model = cls.build(case, cls.spec(model_spec(case)))
    tri = model.volume.elements
    m = skfem.MeshTri(model.points.T, tri.T)
    lam, mu = lame_parameters(E, NU)
    K = skfem.asm(
        linear_elasticity(2 * lam * mu / (lam + 2 * mu), mu),
        skfem.Basis(m, skfem.ElementVector(skfem.ElementTriP1())),
    ).toarray()
    s = 1 / np.sqrt(np.repeat(model.masses, 2))
    omega = np.sqrt(np.linalg.eigvalsh(s[:, None] * K * s[None, :]).max())
    assert p1["dt_stable"] == pytest.approx(2 / omega, rel=1e-9)
