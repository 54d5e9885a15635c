"""Fixtures of the command tests: ``made`` (a tiny case, the network it builds, points for
the reference, a tiny tet mesh; once per module) and ``cache`` (the reference cache in
that folder; the bad-input modules use it for every test)."""

import meshio
import pytest

from harness import cli
from tests.commands.inputs import CASE, cube_tets


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A tiny case, the network it builds, points for the reference, a tiny tet mesh."""
    d = tmp_path_factory.mktemp("inputs")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SPRINGBENCH_CACHE", str(d / "cache"))
        (d / "tiny.toml").write_text(CASE)
        (d / "points.csv").write_text("x,y\n0.5,0.5\n1.5,0.25\n")
        meshio.write(d / "cube.vtu", meshio.Mesh(*cube_tets()[:1], [("tetra", cube_tets()[1])]))
        assert cli.main(["build", str(d / "tiny.toml"), "--out", str(d / "net.vtu")]) == 0
        yield d


@pytest.fixture
def cache(made, monkeypatch):
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(made / "cache"))
