"""The front-door documents: the docs build with mkdocs --strict (broken links and anchors
fail), README is short, opens with the two commands CI runs and says no history, its
results table and docs/commands.md are what their generators give, the code's citations of
the docs name sections that exist, and LICENSE and CITATION.cff say what pyproject says."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DOCS = ROOT / "docs"

# phrases that tell the past of the code (history belongs in CHANGELOG.md); the words are
# spelt with a character class, so this file does not match itself
HISTORY = [
    r"\bused t[o]\b",
    r"\bprev[i]ously\b",
    r"\bform[e]rly\b",
    r"\bw[a]s ~",
    r"\bw[e]re ~",
    r"\bthe o[l]d ",
    r"\bth[i]s session\b",
    r"\bearlier r[u]ns\b",
    r"\bno l[o]nger\b",
    r"\bn[o]w\b",
    r"\bany ?mo[r]e\b",
    r"\bhad be[e]n\b",
    r"\bthe new def[a]ult\b",
    r"\bbefore th[e]\b (?:change|fix|rewrite|solver|caching)",
]


def _markdown_pages() -> list[Path]:
    return sorted(p for p in DOCS.rglob("*.md"))


def _nav_files(nav) -> list[str]:
    out = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        out += _nav_files(value) if isinstance(value, list) else [value]
    return out


def _mkdocs_config() -> dict:
    yaml = pytest.importorskip("yaml", reason="PyYAML (a dependency of mkdocs) is not installed")

    class Loader(yaml.SafeLoader):  # mkdocs.yml may hold !!python tags; none are needed here
        pass

    Loader.add_multi_constructor("tag:yaml.org,2002:python/", lambda loader, suffix, node: None)
    return yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=Loader)


# -- the docs site -----------------------------------------------------------------------------


@pytest.mark.slow
def test_mkdocs_build_strict(tmp_path):
    """mkdocs build --strict: every link between pages, to an anchor, to the results (added by
    docs/hooks/repo_files.py) resolves, or the build fails."""
    pytest.importorskip(
        "mkdocs",
        reason="mkdocs is not installed: pip install -e '.[test]' installs mkdocs-material",
    )
    pytest.importorskip(
        "material", reason="the material theme is not installed: pip install mkdocs-material"
    )
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    res = subprocess.run(
        (
            [sys.executable, "-m", "mkdocs", "build", "--strict"]
            + ["-f", str(ROOT / "mkdocs.yml"), "-d", str(site)]
        ),
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    for page in _nav_files(_mkdocs_config()["nav"]):
        html = site / (page[: -len(".md")] if page != "index.md" else "") / "index.html"
        assert html.is_file(), f"{page} was not built ({html})"
    # the results page and what it shows came along
    assert (site / "results" / "README" / "index.html").is_file()
    assert (site / "results" / "nu_sweep" / "fig-nu-sweep.png").is_file()
    assert (site / "examples" / "lug.msh").is_file()


def test_every_page_is_in_the_nav():
    nav = set(_nav_files(_mkdocs_config()["nav"]))
    pages = {p.relative_to(DOCS).as_posix() for p in _markdown_pages()}
    assert pages - nav == set(), "pages missing from mkdocs.yml's nav"
    missing = {p for p in nav - pages if not (ROOT / p).is_file()}
    assert missing == set(), "nav entries with no page"


@pytest.mark.parametrize(
    "path",
    [README, ROOT / "cases" / "README.md", *sorted(DOCS.glob("*.md"))],
    ids=lambda p: p.relative_to(ROOT).as_posix(),
)
def test_links_resolve_in_the_repository_too(path):
    """Read on GitHub, every relative link of README, cases/README.md and the docs pages names
    a file of the repository (the site reads ../results/ and ../examples/ through the hook)."""
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    targets = [m.split("#")[0] for m in re.findall(r"\]\(([^)\s]+)\)", text)]
    broken = [t for t in targets if t and "://" not in t and not (path.parent / t).exists()]
    assert broken == [], f"{path.name}: links to nothing: {broken}"


def test_the_hook_follows_links_from_the_results_page(tmp_path):
    """docs/hooks/repo_files.py adds the results page and every file it links to, through
    Markdown and HTML, and nothing outside the repository or not linked."""
    sys.path.insert(0, str(DOCS / "hooks"))
    try:
        pytest.importorskip("mkdocs")
        from repo_files import linked
    finally:
        sys.path.remove(str(DOCS / "hooks"))
    (tmp_path / "r" / "a").mkdir(parents=True)
    (tmp_path / "r" / "README.md").write_text(
        "[t](a/t.md) ![f](a/f.png) [p](index.html#x) [w](https://x.org/y.png) "
        "[up](../outside.md) [gone](a/gone.csv)"
    )
    (tmp_path / "r" / "a" / "t.md").write_text("[back](../README.md) [c](c.csv)")
    (tmp_path / "r" / "a" / "f.png").write_bytes(b"png")
    (tmp_path / "r" / "a" / "c.csv").write_text("x\n")
    (tmp_path / "r" / "a" / "unlinked.png").write_bytes(b"png")
    (tmp_path / "r" / "index.html").write_text("<img src='a/g.png'><a href=\"#top\">top</a>")
    (tmp_path / "r" / "a" / "g.png").write_bytes(b"png")
    (tmp_path / "outside.md").write_text("outside")
    got = linked(tmp_path / "r", "README.md")
    assert got == ["README.md", "a/c.csv", "a/f.png", "a/g.png", "a/t.md", "index.html"]


# -- README ------------------------------------------------------------------------------------


def test_readme_is_short_and_opens_with_the_two_commands_ci_runs():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines (at most 150)"
    assert lines[0] == "# springbench"
    first_block = lines[lines.index("```bash") + 1 : lines.index("```bash") + 3]
    assert first_block[0] == "pip install -q -e . && springbench run"
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    ci_command = [line.strip() for line in ci.splitlines() if "python -m pytest" in line]
    assert ci_command == [first_block[1]], (
        "README's second command must be exactly what .ci/run runs"
    )
    assert lines.index("```bash") < 5, "the commands come first"


@pytest.mark.parametrize(
    "path",
    [
        README,
        *sorted((ROOT / "docs").glob("*.md")),
        ROOT / "cases" / "README.md",
        ROOT / "examples" / "make_lug.py",
    ],
    ids=lambda p: p.relative_to(ROOT).as_posix(),
)
def test_no_history_outside_the_changelog(path):
    """README and the docs say what is; the past belongs in CHANGELOG.md."""
    text = path.read_text(encoding="utf-8")
    text = re.sub(r"```.*?```", "", text, flags=re.S)  # pasted program output is not prose
    hits = [
        (m.group(0), text[max(0, m.start() - 40) : m.end() + 40].replace("\n", " "))
        for pattern in HISTORY
        for m in re.finditer(pattern, text, flags=re.I)
    ]
    assert hits == [], f"history phrases in {path.name}: {hits}"


def test_the_history_check_can_fail():
    was, session, now, used = "w" + "as ~", "th" + "is session", "n" + "ow", "used t" + "o"
    text = (
        f"The solver {was}8 min before {session}; {now} it takes 90 s. It {used} refine uniformly."
    )
    hits = [p for p in HISTORY if re.search(p, text, flags=re.I)]
    assert len(hits) >= 4, hits


def test_readme_results_table_is_what_the_results_give():
    from harness.report.docs_gen import BEGIN, END, block, heldout_table

    assert block(README.read_text(encoding="utf-8"), BEGIN, END) == heldout_table(
        ROOT / "results"
    ), "README's results table differs from results/bench/heldout.csv: run python docs/generate.py"


def test_the_results_table_reads_the_bench_csv(tmp_path):
    """The generator on a hand-made heldout.csv: rows per body and nu, the best rule's own error
    looked up, the overall ratio from the 'all' row."""
    from harness.report.docs_gen import heldout_table

    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "heldout.csv").write_text(
        "body,n_tets,nu,model,choice,rule,load,err,best_rule,ratio_to_best_rule\n"
        "part,1234,0.3,calibrate,springs-prior1,vangelder,geomean,0.02,lloyd,0.5\n"
        "part,1234,0.3,calibrate,springs-prior1,vangelder,tip,0.9,lloyd,0.7\n"
        "part,1234,0.3,lloyd,rule,lloyd,geomean,0.04,lloyd,1.0\n"
        "part,1234,0.3,vangelder,rule,vangelder,geomean,0.05,lloyd,1.25\n"
        "part,1234,0.45,calibrate,rule,cauchy,geomean,0.07,cauchy,1.0\n"
        "part,1234,0.45,cauchy,rule,cauchy,geomean,0.07,cauchy,1.0\n"
        "all,,,calibrate,,,geomean,,,0.7071\n"
    )
    rows = heldout_table(tmp_path).splitlines()
    row = "| part (1,234) | 0.3 | springs-prior1 fitted from vangelder | 0.02 | lloyd | 0.04 "
    row += "| 0.500 |"
    assert rows[2] == row
    assert rows[3] == "| part (1,234) | 0.45 | the rule cauchy | 0.07 | cauchy | 0.07 | 1.000 |"
    assert rows[4] == "| all (geometric mean) | | | | | | **0.707** |"
    assert len(rows) == 5
    # with the truth's own error measured, a column of it (the geomean row's: its loads' largest)
    csv = tmp_path / "bench" / "heldout.csv"
    lines = csv.read_text().splitlines()
    lines = [lines[0] + ",truth_error"] + [
        x + (",0.003" if "geomean" in x else ",") for x in lines[1:]
    ]
    csv.write_text("\n".join(lines) + "\n")
    rows = heldout_table(tmp_path).splitlines()
    assert rows[0].endswith("| ratio | truth's error |") and rows[2] == row + " <= 0.003 |"
    assert rows[4] == "| all (geometric mean) | | | | | | **0.707** | |"


def test_the_scale_table_is_what_the_bench_gives(tmp_path):
    """docs/calibrate.md's scale table is the generator's on results/bench/calibrate.csv; the
    generator on a hand-made file: the ratio of the export's held-out error to the best
    rule's, the fit's time over the rule alone's, a row without a level (a rule)."""
    from harness.report.docs_gen import SCALE_BEGIN, SCALE_END, block, scale_table

    page = (DOCS / "calibrate.md").read_text(encoding="utf-8")
    assert block(page, SCALE_BEGIN, SCALE_END) == scale_table(ROOT / "results"), (
        "docs/calibrate.md's scale table differs from results/bench/calibrate.csv: "
        "run python docs/generate.py"
    )
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "calibrate.csv").write_text(
        "body,n_tets,seconds,rule_seconds,peak_gb,choice,fit_level,G_heldout_mean,best_rule,"
        "G_heldout_mean_best_rule\n"
        "cylinder,48880,150,100,2.5,scale+node-volume,3,0.02,learned,0.05\n"
        "bracket,31389,300,200,5.0,rule,,0.06,learned,0.06\n"
    )
    rows = scale_table(tmp_path).splitlines()
    assert rows[2] == (
        "| cylinder (48,880) | scale+node-volume (3) | 2.00 % | 5.00 % (learned) | 0.40 "
        "| 150 s | 100 s | 0.50 | 2.5 GB |"
    )
    assert rows[3].startswith("| bracket (31,389) | rule | 6.00 % | 6.00 % (learned) | 1.00 ")
    assert len(rows) == 4


def test_commands_page_is_what_the_command_line_gives():
    from harness.cli import build_parser
    from harness.report.docs_gen import CMD_BEGIN, CMD_END, block, commands_reference

    text = (DOCS / "commands.md").read_text(encoding="utf-8")
    assert block(text, CMD_BEGIN, CMD_END) == commands_reference(build_parser()), (
        "docs/commands.md differs from the command line's help: run python docs/generate.py"
    )


def test_commands_reference_lists_every_command_and_flag():
    """The generator itself: every command registered in the CLI and every option string of
    its parser (sub-commands included) is in the page."""
    import argparse

    from harness.cli import build_parser
    from harness.report.docs_gen import commands_reference

    page = commands_reference(build_parser())

    def walk(parser, name):
        assert f"`{name}`" in page, name
        for a in parser._actions:
            if isinstance(a, argparse._SubParsersAction):
                for sub_name, sub in a.choices.items():
                    walk(sub, f"{name} {sub_name}")
            for opt in a.option_strings:
                if opt not in ("-h", "--help"):
                    assert f"`{opt}`" in page, f"{name} {opt}"

    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    for name, parser in sub.choices.items():
        walk(parser, f"springbench {name}")


# -- citations of the docs in the code ---------------------------------------------------------


def _headings(page: Path) -> set[str]:
    return {
        m.group(1).strip()
        for m in re.finditer(r"^#{1,6} (.+)$", page.read_text(encoding="utf-8"), flags=re.M)
    }


def test_the_code_cites_sections_that_exist():
    """``docs/<page>.md, "Section"`` in the code and tests names a heading of that page, and no
    citation points at the design sketch outside the repository."""
    cited = 0
    for folder in ("harness", "reference", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            if path == Path(__file__).resolve():
                continue
            text = path.read_text(encoding="utf-8")
            assert "DESIGN.md" not in text, (
                f"{path}: cites DESIGN.md (its content is docs/design.md)"
            )
            for m in re.finditer(r"docs/([\w-]+)\.md(?:,\s*|\s*\()\s*\"([^\"]+)\"", text):
                page, section = DOCS / f"{m.group(1)}.md", " ".join(m.group(2).split())
                assert page.is_file(), f"{path}: cites {page.name}, which does not exist"
                assert section in _headings(page), (
                    f"{path}: cites '{section}', not a heading of {page.name}"
                )
                cited += 1
            for m in re.finditer(r"docs/([\w-]+)\.md", text):
                assert (DOCS / f"{m.group(1)}.md").is_file(), f"{path}: cites docs/{m.group(1)}.md"
    assert cited >= 10


# -- LICENSE and CITATION.cff ------------------------------------------------------------------


def _pyproject() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def test_license_is_the_one_pyproject_names():
    assert _pyproject()["project"]["license"] == {"text": "MIT"}
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License\n")
    assert re.search(r"^Copyright \(c\) \d{4} springbench developers$", text, flags=re.M)
    assert 'THE SOFTWARE IS PROVIDED "AS IS"' in text


def test_citation_file_is_cff_1_2_0_and_cites_the_software_and_both_papers():
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0"
    for key in ("message", "title", "authors"):  # required by CFF 1.2.0
        assert cff.get(key), key
    assert cff["type"] == "software"
    assert cff["version"] == _pyproject()["project"]["version"]
    assert cff["license"] == "MIT"
    allowed = {"family-names", "given-names", "name", "affiliation", "orcid", "email", "website"}
    refs = cff["references"]
    titles = [r["title"] for r in refs]
    assert any("Simulated Annealing" in t and "Deformable Bodies" in t for t in titles), titles
    assert any("Controlling Anisotropy in Mass-Spring Systems" == t for t in titles), titles
    for entity in [*cff["authors"], *(a for r in refs for a in r["authors"])]:
        assert set(entity) <= allowed and ("name" in entity or "family-names" in entity), entity
    for r in refs:
        assert r["type"] in {"conference-paper", "article", "proceedings", "book"}
        assert isinstance(r["year"], int) and 1900 < r["year"] < 2100
