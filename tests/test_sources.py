"""harness/sources.py, the one code-hash scheme of the reference cache and the runner: every
.py file under the folders counts (sub-folders too), and a change of a file's bytes or of
its path changes the digest."""

import os

from harness import sources
from reference import cache


def test_the_digest_follows_bytes_and_paths_in_sub_folders(tmp_path, monkeypatch):
    monkeypatch.setattr(sources, "ROOT", tmp_path)
    (tmp_path / "a" / "b").mkdir(parents=True)
    (tmp_path / "a" / "x.py").write_text("x = 1\n")
    deep = tmp_path / "a" / "b" / "y.py"
    deep.write_text("y = 1\n")
    (tmp_path / "a" / "notes.txt").write_text("not code\n")
    shas = sources.tree_shas(["a"])
    assert list(shas) == ["a/b/y.py", "a/x.py"]
    before = sources.digest(shas)
    deep.write_text("y = 2\n")
    os.utime(deep, ns=(1, 1))  # a new mtime: the sha cache is keyed by size and mtime
    assert sources.digest(sources.tree_shas(["a"])) != before
    deep.write_text("y = 1\n")
    os.utime(deep, ns=(2, 2))
    assert sources.digest(sources.tree_shas(["a"])) == before
    deep.rename(tmp_path / "a" / "b" / "z.py")
    assert sources.digest(sources.tree_shas(["a"])) != before


def test_the_reference_cache_hashes_the_reference_rooms():
    shas = sources.tree_shas(cache.CODE)
    assert {
        "reference/graded/levels.py",
        "reference/solvers/plan.py",
        "reference/adaptive/adapt.py",
        "reference/solution.py",
        "harness/case/reader.py",
    } <= set(shas)
    assert cache.code_version() == sources.digest(shas)
