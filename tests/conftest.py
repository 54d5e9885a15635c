"""Fixtures shared across the test folders (the tests are packages: ``tests.run.test_runner``;
shared helpers are modules here: meshes.py, plate_case.py, fakestage.py, fs_faults.py, ...)."""

import os
from pathlib import Path

import pytest

from harness import registry
from tests.fakestage import FAKE

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def fake(monkeypatch):
    """The fake stage (tests/fakestage.py) in place of the real ones, also in worker processes."""
    monkeypatch.setattr(registry, "STAGES", registry.STAGES.with_entries({"fake": FAKE}))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    """The reference cache in the test's own folder (an empty one: every solve is fresh)."""
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
