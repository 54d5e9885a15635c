"""Case files for the reference tests: a rectangle or box with any cell, element and
material (rect_case), any case text (make_case) and the relative error they are judged by."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from harness.case.reader import load_case

ROOT = Path(__file__).resolve().parents[2]


def make_case(tmp_path, text: str, name="c"):
    p = tmp_path / f"{name}.toml"
    p.write_text(textwrap.dedent(text))
    return load_case(p)


def rect_case(
    tmp_path,
    cell,
    element,
    *,
    dim=2,
    E=3.7e3,
    nu=0.27,
    extra="",
    loads='set = "basic2d"\nmagnitude = 2.5',
    divisions=2,
    max_refine=0,
):
    if dim == 2:
        body = 'shape = "rectangle"\norigin = [0.3, -1.2]\nsize = [2.5, 0.8]'
    else:
        body = 'shape = "box"\norigin = [0.3, -1.2, 4.0]\nsize = [2.5, 0.8, 1.3]'
    return make_case(
        tmp_path,
        f"""
name = "t"
dim = {dim}
[body]
{body}
[material]
E = {E}
nu = {nu}
plane = "stress"
{extra}
[loads]
{loads}
[reference]
cell = "{cell}"
element = "{element}"
divisions = {divisions}
max_refine = {max_refine}
""",
    )


def rel_err(u, exact):
    return np.linalg.norm(u - exact, axis=1).max() / np.linalg.norm(exact, axis=1).max()
