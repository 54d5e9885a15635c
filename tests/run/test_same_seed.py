"""Same seed, same table: two runs of a small suite, the first on a cold
reference cache, the second warm and with two workers, write the same summary.csv in
every column that is not a timing (nor ``cached``, which says which run was cold)."""

import pandas as pd
import pytest

from harness import cli
from harness.report.build import TIMING
from tests.plate_case import plate_case

TABLES = """
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


def case(name: str, placement: str, model: str) -> str:
    return plate_case(
        name, TABLES.format(placement=placement, model=model), loads='heldout = ["shear-y"]'
    )


@pytest.mark.slow
def test_two_runs_write_the_same_table(tmp_path, monkeypatch):
    suite = tmp_path / "cases" / "tiny"
    suite.mkdir(parents=True)
    (suite / "grid.toml").write_text(
        case("grid", "grid", 'grid = [5, 3]\nstructure = "structure1"')
    )
    (suite / "lloyd.toml").write_text(case("lloyd", "lloyd", "n_points = 14\nlloyd_iterations = 5"))
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))  # empty: the first run is cold
    tables = []
    for out, jobs in (("a", "1"), ("b", "2")):
        assert (
            cli.main(
                (
                    ["run", str(suite), "--jobs", jobs, "--no-figures"]
                    + ["--results", str(tmp_path / out)]
                )
            )
            == 0
        )
        df = pd.read_csv(tmp_path / out / "tiny" / "summary.csv")
        tables.append(df[[c for c in df.columns if not TIMING.search(c) and c != "cached"]])
    assert (
        len(tables[0]) >= 8
        and "G_heldout" in tables[0]
        and tables[0]["G_heldout"].notna().sum() >= 8
    )
    pd.testing.assert_frame_equal(tables[0], tables[1], check_exact=True)
