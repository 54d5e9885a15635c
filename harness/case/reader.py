"""Case files (TOML) -> frozen ``Case``. Every mistake is a one-line ``CaseError``.

The schema of the core sections (body, material, loads, reference) lives here; the
sections that later stages own (model, optimizer, score, expect, dynamics, ...) are
registered in :mod:`harness.case.sections`. ``[quick]`` and ``[full]`` hold partial
cases merged over the base for ``--quick`` / ``--full`` runs. Schema: docs/case-files.md.
"""

from __future__ import annotations

import hashlib
import tomllib
from pathlib import Path
from types import MappingProxyType

import numpy as np

from harness.case import sections as case_sections
from harness.case.case import Body, Case, Fibre, Material, ReferenceSpec, Region
from harness.case.elasticity import transversely_isotropic_compliance
from harness.case.fields import GRADED_LEVELS, TOP
from harness.case.loads import (
    parse_heldout,
    parse_loads,
    parse_rank_by,
    parse_validation,
    with_anchors,
)
from harness.case.mesh_checks import COORDINATE_FIX, coordinate_problem
from harness.case.schema import Field, check, describe, did_you_mean
from harness.case.selectors import SPELLINGS, case_part
from harness.errors import CaseError, SpringbenchError, raise_all
from harness.io.end_faces import BAND, COS, EndPart
from harness.io.mesh_groups import GroupPart, require_group
from harness.io.meshfile import read_mesh

MODES = ("quick", "full")

# -- loading --------------------------------------------------------------------------


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def load_case(path, mode: str = "quick") -> Case:
    """Read and validate a case file; any mistake is a one-line CaseError.

    Parameters
    ----------
    path : str or Path
        The TOML case file (schema: docs/case-files.md).
    mode : {"quick", "full"}
        The table merged over the base: the case's ``[quick]`` or ``[full]``.

    Returns
    -------
    Case
    """
    path = Path(path)
    file = str(path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise CaseError("file not found", file=file, fix="check the path")
    except IsADirectoryError:
        raise CaseError("a folder, not a case file", file=file, fix="give a .toml case file")
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"not valid TOML ({exc})", file=file, fix="fix the syntax at that line")
    except UnicodeDecodeError:
        raise CaseError("not a text file", file=file, fix="case files are UTF-8 TOML")
    return case_of(raw, path, mode, hashlib.sha256(path.read_bytes()).hexdigest())


def case_of(
    raw: dict, path: Path, mode: str = "quick", digest: str = "", material: Material | None = None
) -> Case:
    """The validated Case of a case table (a case file's parsed TOML, or one a command
    builds in memory); ``path`` names it in errors and anchors its relative files;
    ``material``: the Material a command built itself (the table's [material] is checked
    and must say the same). Mistakes are one-line CaseErrors, as for :func:`load_case`."""
    file = str(path)
    for m in MODES:
        if m in raw and not isinstance(raw[m], dict):
            raise CaseError("expected a table", file=file, field=m)
    raw = _merge({k: v for k, v in raw.items() if k not in MODES}, raw.get(mode, {}))
    core = {k: v for k, v in raw.items() if k in TOP}
    rest = {k: v for k, v in raw.items() if k not in TOP}
    errors, sections = [], {}  # the schema's mistakes in every section, one line each
    try:
        d = check(core, TOP, file)
    except CaseError as exc:
        errors.append(exc)
    for key, value in rest.items():
        try:
            sections[key] = MappingProxyType(_section(key, value, file))
        except CaseError as exc:
            errors.append(exc)
    raise_all(errors)
    dim = d["dim"]
    body = _body(d["body"], dim, path, file)
    material = _same(material, _material(d["material"], dim, file), file)
    body = with_anchors(d["loads"], body, file)
    loads, load_set = parse_loads(d["loads"], dim, body, file)
    validation = parse_validation(d["loads"], loads, file)
    heldout = parse_heldout(d["loads"], loads, file, validation)
    fitted = [c.name for c in loads if c.name not in set(heldout) | set(validation)]
    rank_by = parse_rank_by(d["loads"], loads, file, fitted)
    reference = _reference(d["reference"], dim, body, file)
    return Case(
        path=path,
        name=d["name"],
        dim=dim,
        body=body,
        material=material,
        loads=loads,
        reference=reference,
        load_set=load_set,
        magnitude=d["loads"]["magnitude"],
        description=d["description"],
        tags=d["tags"],
        mode=mode,
        sections=MappingProxyType(sections),
        digest=digest,
        heldout=heldout,
        validation=validation,
        rank_by=rank_by,
    )


def _same(given: Material | None, read: Material, file: str) -> Material:
    """The material a command built, when it agrees with its table's; else the table's."""
    if given is not None and given != read:
        raise CaseError(f"{given} differs from the table's {read}", file=file, field="material")
    return read if given is None else given


def _section(key: str, value, file: str) -> dict:
    """A stage-owned section checked against its spec ([model]: the spec of its kind)."""
    if key not in case_sections.SECTIONS:
        raise CaseError(
            "unknown section",
            file=file,
            field=key,
            fix=did_you_mean(key, set(TOP) | set(case_sections.SECTIONS) | set(MODES)),
        )
    spec = case_sections.SECTIONS[key]
    if spec == "model":
        kinds = case_sections.MODEL_KINDS
        if not isinstance(value, dict):
            raise CaseError(
                f"expected a table, got {describe(value)}",
                file=file,
                field=key,
                fix=f"a [model] table with kind = one of {', '.join(kinds)}",
            )
        kind = value.get("kind")
        if not isinstance(kind, str) or kind not in kinds:
            raise CaseError(
                f"unknown or missing model kind {kind!r}",
                file=file,
                field="model.kind",
                fix=f"one of {', '.join(kinds)}",
            )
        spec = {"kind": Field("str"), **kinds[kind]}
    return check(value, spec, file, key + ".")


def _box_body(b: dict, dim: int, fail) -> Body:
    """A rectangle or box body: its size and origin checked."""
    shape = b["shape"]
    want = 2 if shape == "rectangle" else 3
    if dim != want:
        fail(
            "shape",
            f"a {shape} needs dim = {want}",
            f"use {'box' if want == 2 else 'rectangle'} or set dim = {want}",
        )
    if b["size"] is None:
        fail("size", "missing required field", f"give {dim} positive extents")
    if len(b["size"]) != dim:
        fail("size", f"expected {dim} entries, got {len(b['size'])}")
    origin = b["origin"] or (0.0,) * dim
    if len(origin) != dim:
        fail("origin", f"expected {dim} entries, got {len(origin)}")
    problem = coordinate_problem([origin, np.add(origin, b["size"])])
    if problem:  # blame the size if it alone is the problem
        fail(
            "size" if coordinate_problem([(0.0,) * dim, b["size"]]) else "origin",
            problem,
            COORDINATE_FIX,
        )
    return Body(shape, origin=origin, size=b["size"])


def _polygon_body(b: dict, dim: int, fail) -> Body:
    """A polygon body: at least three vertices enclosing an area."""
    if dim != 2:
        fail("shape", "a polygon needs dim = 2")
    v = b["vertices"]
    if v is None or len(v) < 3 or any(len(p) != 2 for p in v):
        fail("vertices", "expected at least 3 points [x, y]")
    if coordinate_problem(v):
        fail("vertices", coordinate_problem(v), COORDINATE_FIX)
    x, y = np.asarray(v, float).T
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    if abs(area) <= 1e-14:
        fail("vertices", "the polygon has zero area", "list the vertices in order around the body")
    return Body("polygon", vertices=v)


def _mesh_body(b: dict, dim: int, path: Path, fail):
    """(the body, its mesh) of a mesh file, read and checked."""
    if not b["file"]:
        fail(
            "file",
            "missing required field for shape = 'mesh'",
            "give the mesh path relative to the case file",
        )
    mpath = (path.parent / b["file"]).resolve()
    try:
        mesh = read_mesh(mpath, b["format"])
        from harness.case.mesh_checks import check_mesh

        check_mesh(mesh, str(mpath))
    except SpringbenchError as exc:
        fail("file", exc.message, exc.fix)
    if mesh.dim != dim:
        fail("file", f"the mesh is {mesh.dim}-D but dim = {dim}", f"set dim = {mesh.dim}")
    return Body(b["shape"], file=mpath, format=b["format"]), mesh


def _box_part(box, name: str, dim: int, fail) -> tuple:
    """A part given as {box = [[lo...], [hi...]]}: its two corners."""
    ok = (
        isinstance(box, list)
        and len(box) == 2
        and all(
            isinstance(r, list)
            and len(r) == dim
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in r)
            for r in box
        )
    )
    if not ok:
        fail(f"parts.{name}.box", f"expected [[lo], [hi]] with {dim} numbers each")
    if np.isnan(np.asarray(box, float)).any():  # every comparison with nan is false
        fail(f"parts.{name}.box", "nan in the box", "give numbers (inf is fine for an open side)")
    if any(lo > hi for lo, hi in zip(*box)):
        fail(f"parts.{name}.box", "lo > hi", "the first corner is the minimum")
    return (tuple(map(float, box[0])), tuple(map(float, box[1])))


def _part(spec, name: str, dim: int, body: Body, mesh, path: Path, file: str, fail):
    """One [body.parts] entry: a mesh group, an end face, facets or a box."""
    if isinstance(spec, dict) and set(spec) == {"group"}:  # a named group of the mesh file
        if body.shape != "mesh" or not isinstance(spec["group"], str):
            fail(
                f"parts.{name}.group",
                "expected the name of a group of the body's mesh file",
                "groups need shape = 'mesh'; elsewhere use {box = [[lo...], [hi...]]}",
            )
        require_group(
            mesh, spec["group"], file=file, field=f"body.parts.{name}.group", error=CaseError
        )
        return GroupPart(spec["group"], body.file, body.format)
    if isinstance(spec, dict) and "end" in spec:  # an end face of the mesh along an axis
        return _end_part(spec, name, body.shape, dim, body, fail)
    if isinstance(spec, dict) and set(spec) == {"facets"}:  # a group, nodes:, box: or sphere:
        return _facets_part(spec["facets"], name, body.shape, mesh, body, path, file, fail)
    if not isinstance(spec, dict) or set(spec) != {"box"}:
        fail(
            f"parts.{name}",
            'expected {box = [[lo...], [hi...]]}, {group = "name"}, {end = "x1"} or '
            '{facets = "box:..."}',
        )
    return _box_part(spec["box"], name, dim, fail)


def _body(b: dict, dim: int, path: Path, file: str) -> Body:
    def fail(fld, msg, fix=None):
        raise CaseError(msg, file=file, field="body." + fld, fix=fix)

    mesh = None
    if b["shape"] in ("rectangle", "box"):
        body = _box_body(b, dim, fail)
    elif b["shape"] == "polygon":
        body = _polygon_body(b, dim, fail)
    else:
        body, mesh = _mesh_body(b, dim, path, fail)
    if not isinstance(b["parts"], dict):
        fail("parts", "expected a table of name = {box = [[lo], [hi]]}")
    parts = {
        name: _part(spec, name, dim, body, mesh, path, file, fail)
        for name, spec in b["parts"].items()
    }
    return Body(
        body.shape,
        body.origin,
        body.size,
        body.vertices,
        body.file,
        body.format,
        MappingProxyType(parts),
    )


def _facets_part(value, name: str, shape: str, mesh, body, path: Path, file: str, fail):
    """``{ facets = "nodes:FILE" | "box:..." | "sphere:..." | "group" }`` of a mesh body
    (harness.case.selectors; a node file relative to the case file)."""
    where = f"parts.{name}.facets"
    if shape != "mesh":
        fail(where, "facets need shape = 'mesh'", "elsewhere use {box = [[lo...], [hi...]]}")
    part = case_part(value, mesh, body, path.parent, lambda msg, fix: fail(where, msg, fix))
    if isinstance(part, str):  # a group's name
        if part not in mesh.groups and ":" in part:
            fail(where, f"'{part}' is neither a group of the mesh nor a selector", SPELLINGS)
        require_group(mesh, part, file=file, field=f"body.{where}", error=CaseError)
        return GroupPart(part, body.file, body.format)
    return part


def _end_part(spec: dict, name: str, shape: str, dim: int, body, fail) -> EndPart:
    """``{ end = "x1", band = 0.05, cos = 0.5 }`` of a mesh body (harness.io.end_faces)."""
    where = f"parts.{name}"
    faces = ("x0", "x1", "y0", "y1", "z0", "z1")[: 2 * dim]
    extra = sorted(set(spec) - {"end", "band", "cos"})
    if extra:
        fail(
            f"{where}.{extra[0]}",
            "unknown key of an end part",
            "an end part takes end, band and cos",
        )
    if shape != "mesh":
        fail(
            f"{where}.end",
            "end faces need shape = 'mesh'",
            "a box's faces are the parts x0, x1, y0, ... already",
        )
    if spec["end"] not in faces:
        fail(
            f"{where}.end",
            f"expected one of {', '.join(faces)}, got {spec['end']!r}",
            "x0 is the low end of the x axis, x1 its high end",
        )
    band, cos = spec.get("band", BAND), spec.get("cos", COS)
    for key, v, ok in (("band", band, lambda v: 0 < v <= 1), ("cos", cos, lambda v: -1 <= v < 1)):
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not ok(v):
            fail(
                f"{where}.{key}",
                f"{v!r} is out of range",
                "band: a fraction of the body's extent in (0, 1], e.g. 0.05; cos: in [-1, "
                "1), e.g. 0.5",
            )
    return EndPart(
        "xyz".index(spec["end"][0]),
        int(spec["end"][1]),
        body.file,
        body.format,
        float(band),
        float(cos),
    )


def _material(m: dict, dim: int, file: str) -> Material:
    def fail(fld, msg, fix=None):
        raise CaseError(msg, file=file, field="material." + fld, fix=fix)

    fibre = None
    if m["fibre"] is not None:
        f = m["fibre"]
        given = [k for k in ("direction", "azimuth_deg", "field") if f[k] is not None]
        if len(given) > 1:
            fail("fibre", f"both {given[0]} and {given[1]} given", "give one fibre direction")
        if not given:
            fail(
                "fibre.direction",
                "missing",
                "give direction, azimuth_deg (+ elevation_deg) or field",
            )
        if f["direction"] is not None:
            if len(f["direction"]) != dim:
                fail("fibre.direction", f"expected {dim} entries")
            if np.linalg.norm(f["direction"]) == 0:
                fail("fibre.direction", "zero vector", "give a non-zero direction")
        if f["field"] is not None and dim != 3:
            fail("fibre.field", "named fields are 3-D", "use direction or azimuth_deg in 2-D")
        nu_f = f["nu_fibre"] if f["nu_fibre"] is not None else m["nu"]
        nu_c = f["nu_cross"] if f["nu_cross"] is not None else m["nu"]
        G = f["G_fibre"] or f["E_fibre"] * f["E_cross"] / (
            f["E_fibre"] + f["E_cross"] * (1 + 2 * nu_f)
        )
        fibre = Fibre(
            f["E_fibre"],
            f["E_cross"],
            nu_f,
            nu_c,
            G,
            f["direction"],
            f["azimuth_deg"],
            f["elevation_deg"],
            f["field"],
            f["seed"],
        )
        S = transversely_isotropic_compliance(fibre.E_fibre, fibre.E_cross, nu_f, nu_c, G)
        if np.linalg.eigvalsh(S).min() <= 0:
            fail(
                "fibre",
                "the compliance is not positive definite",
                "need 1 - nu_cross - 2 nu_fibre^2 E_cross/E_fibre > 0",
            )
    regions = []
    for i, r in enumerate(m["regions"]):
        box = r["box"]
        if len(box) != 2 or any(len(p) != dim for p in box):
            fail(f"regions[{i}].box", f"expected [[lo], [hi]] with {dim} numbers each")
        regions.append(Region(box[0], box[1], r["E"], r["nu"], r["density"]))
    if m["plane"] == "strain" and dim == 3:
        pass  # irrelevant in 3-D; accepted for symmetry
    return Material(m["E"], m["nu"], m["density"], m["plane"], fibre, tuple(regions))


def _reference(r: dict, dim: int, body: Body, file: str) -> ReferenceSpec:
    cell = r["cell"] or ("tri" if dim == 2 else "tet")
    if (cell in ("tri", "quad")) != (dim == 2):
        raise CaseError(
            f"cell '{cell}' does not fit dim = {dim}",
            file=file,
            field="reference.cell",
            fix="tri/quad in 2-D, tet/hex in 3-D",
        )
    if body.shape == "polygon" and cell == "quad":
        raise CaseError(
            "a polygon is meshed with triangles", file=file, field="reference.cell", fix="use tri"
        )
    method = r["method"]
    if method == "auto":
        method = (
            "graded"
            if (body.shape == "box" and r["cell"] in (None, "hex") and r["element"] == "P2")
            else "refine"
        )
    if method == "graded":
        if body.shape not in ("rectangle", "box"):
            raise CaseError(
                f"graded reference meshes need a rectangle or box (the body is a {body.shape})",
                file=file,
                field="reference.method",
                fix='use method = "refine"',
            )
        if r["cell"] not in (None, "quad", "hex") or r["element"] != "P2":
            raise CaseError(
                "graded reference meshes are Q2 quadrilaterals/hexahedra",
                file=file,
                field="reference.method",
                fix='drop reference.cell and element, or use method = "refine"',
            )
        cell = "quad" if dim == 2 else "hex"
    levels = (
        r["max_refine"]
        if r["max_refine"] is not None
        else (GRADED_LEVELS if method == "graded" else 3)
    )
    return ReferenceSpec(
        r["element"], cell, r["divisions"], r["tol"], levels, r["solver"], r["modes"], method
    )


def find_cases(paths) -> list[Path]:
    """Case files named by ``paths`` (files or folders, searched recursively), sorted."""
    out = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(q for q in p.rglob("*.toml") if not q.name.startswith("_"))
            if not found:  # a wrong folder, not a suite with nothing to do
                raise SpringbenchError(
                    "no case files (*.toml) in this folder",
                    file=str(p),
                    fix="give case files or a folder of them, e.g. cases/",
                )
            out.extend(found)
        elif p.exists():
            out.append(p)
        else:
            raise SpringbenchError("no such file or folder", file=str(p), fix="check the path")
    return out
