"""Same seed, same table (issue 13): two runs of a small suite, the first on a cold
reference cache, the second warm and with two workers, write the same summary.csv in
every column that is not a timing (nor ``cached``, which says which run was cold)."""

import textwrap

import pandas as pd
import pytest

from harness import cli
from harness.report.build import TIMING

CASE = """
name = "{name}"
dim = 2
[body]
shape = "rectangle"
size = [2.0, 1.0]
[material]
E = 1000.0
nu = 0.3
[loads]
set = "basic2d"
heldout = ["shear-y"]
[reference]
divisions = 4
max_refine = 1
modes = 4
[model]
kind = "sms"
placement = "{placement}"
{model}
masses = "moments-nonneg"
stiffness = ["deussen", "lloyd"]
[optimizer]
method = "sa"
options = {{ temperatures = 4 }}
compare = ["lbfgs"]
compare_options = {{ lbfgs = {{ maxiter = 60 }} }}
[optimizer.frequency]
modes = 3
options = {{ maxiter = 60 }}
"""


@pytest.mark.slow
def test_two_runs_write_the_same_table(tmp_path, monkeypatch):
    suite = tmp_path / "cases" / "tiny"
    suite.mkdir(parents=True)
    (suite / "grid.toml").write_text(textwrap.dedent(CASE.format(
        name="grid", placement="grid", model='grid = [5, 3]\nstructure = "structure1"')))
    (suite / "lloyd.toml").write_text(textwrap.dedent(CASE.format(
        name="lloyd", placement="lloyd", model="n_points = 14\nlloyd_iterations = 5")))
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))      # empty: the first run is cold
    tables = []
    for out, jobs in (("a", "1"), ("b", "2")):
        assert cli.main(["run", str(suite), "--jobs", jobs, "--no-figures", "--results", str(tmp_path / out)]) == 0
        df = pd.read_csv(tmp_path / out / "tiny" / "summary.csv")
        tables.append(df[[c for c in df.columns if not TIMING.search(c) and c != "cached"]])
    assert len(tables[0]) >= 8 and "G_heldout" in tables[0] and tables[0]["G_heldout"].notna().sum() >= 8
    pd.testing.assert_frame_equal(tables[0], tables[1], check_exact=True)
