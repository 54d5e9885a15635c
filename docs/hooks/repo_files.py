"""mkdocs hook: the repository files the docs link to, added to the site as they are.

The published results (``results/README.md``, written by ``springbench report``, and every
file it links to, following links through Markdown and HTML files) and the shipped example
(``examples/``) live outside ``docs/``. They are added to the site under their repository
paths. A page links to them as the repository has them, ``../results/README.md`` from
``docs/``, so the link works on GitHub too; for the site that link is read as
``results/README.md``, and ``mkdocs build --strict`` checks it like any other.
"""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOTS = ("results/README.md", "examples/lug.msh", "examples/make_lug.py")
# ](../results/...) in a page of docs/
UP = re.compile(r"\]\(\.\./((?:results|examples)/[^)\s]*)\)")
LINK = re.compile(r"""\]\(([^)\s]+)\)|(?:src|href)=["']([^"']+)["']""")


def linked(repo: Path, start: str) -> list[str]:
    """``start`` and every repository file reachable from it by relative links (Markdown and
    HTML files are followed, other files are leaves), each as a path relative to ``repo``."""
    seen, todo = [], [start]
    while todo:
        rel = todo.pop()
        if rel in seen or not (repo / rel).is_file():
            continue
        seen.append(rel)
        if not rel.endswith((".md", ".html")):
            continue
        for a, b in LINK.findall((repo / rel).read_text(encoding="utf-8")):
            target = (a or b).split("#")[0]
            if not target or "://" in target or target.startswith(("/", "mailto:")):
                continue
            path = (repo / rel).parent.joinpath(target).resolve()
            if path.is_relative_to(repo) and path.is_file():
                todo.append(path.relative_to(repo).as_posix())
    return sorted(seen)


def on_files(files: Files, config) -> Files:
    repo = Path(config.config_file_path).resolve().parent
    for start in ROOTS:
        for rel in linked(repo, start):
            if files.get_file_from_path(rel) is not None:
                continue
            f = File.generated(config, rel, abs_src_path=str(repo / rel))
            if Path(rel).name == "README.md":  # a README page would be its folder's index.html
                stem = rel[: -len(".md")]
                f.dest_uri = f"{stem}/index.html" if config.use_directory_urls else f"{stem}.html"
            files.append(f)
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:
    """A top-level page's ``../results/`` and ``../examples/`` links, as the site has them."""
    if "/" in page.file.src_uri:
        return markdown
    return UP.sub(r"](\1)", markdown)
