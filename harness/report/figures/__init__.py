"""Figure registry: each figure kind is one module listed in ``FIGURES``.

A figure module has ``NAME``, ``SCOPE`` ("case": drawn per case data folder; "suite":
drawn once per suite folder from its summary.csv; "bench": once from the bench CSVs), ``DATA``
(globs of the files it reads in
the folder; or ``inputs(folder) -> list[Path]`` when it reads others too), optionally
``CODE`` (the other modules its drawing depends on) and ``make(folder) -> list[Path]``,
which reads stored data files (formats in :mod:`harness.report.build`), writes PNGs into
``folder`` and returns their paths; no data file, no figure (an empty list). Figures
never recompute anything. A figure that fails is reported as one warning line and the
report carries on.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import re
import sys
from pathlib import Path

import numpy as np

from harness.outputs import staged, write_changed

FIGURES = [
    "harness.report.figures.trace",  # G against SA steps (trace.csv)
    # Lloyd statistics against iterations, Deussen Fig. 2 (lloyd.csv)
    "harness.report.figures.lloyd",
    # G per Lloyd iteration count, Deussen Fig. 12 (summary.csv)
    "harness.report.figures.lloyd_bars",
    "harness.report.figures.volume",  # volume variation, Bourguignon-Cani Fig. 3 (volume.csv)
    "harness.report.figures.spectrum",  # natural frequencies model vs FEM (frequencies.csv)
    "harness.report.figures.anisotropy",  # polar plot of effective stiffness (anisotropy.csv)
    "harness.report.figures.deformed",  # reference vs model deformed shapes (deformed*.npz)
    "harness.report.figures.fibres",  # fibre fields, Bourguignon-Cani Fig. 6 (fibres.npz)
    "harness.report.figures.nu_sweep",  # G against Poisson's ratio per model class (summary.csv)
    # each engine's G_norm against nu (the engines suite's summary.csv)
    "harness.report.figures.engines",
    # the benchmarks' plot: FEM solve time and error (bench/reference.csv)
    "harness.report.figures.bench_reference",
    # the engine table: each engine's G_norm against nu (bench/engines.csv)
    "harness.report.figures.bench_engines",
]


def figure_modules(scope: str | None = None):
    mods = [importlib.import_module(n) for n in FIGURES]
    return [m for m in mods if scope is None or m.SCOPE == scope]


def _make(mods, folder: Path) -> list[Path]:
    out = []
    for m in mods:
        try:
            out += [Path(p) for p in m.make(Path(folder))]
        except Exception as exc:  # a broken data file must not stop the report
            why = f"{type(exc).__name__}: {exc}".replace("\n", " ")
            print(f"springbench: warning: figure {m.NAME} in {folder}: {why}", file=sys.stderr)
        finally:
            plt = sys.modules.get("matplotlib.pyplot")
            if plt is not None:
                plt.close("all")
    return out


STAMP = ".figures.json"


def _stamp(files, mods) -> str:
    """What figures depend on: the bytes of their data files (by name) and the figure code;
    never a time, so a fresh checkout or a copy of the results finds its figures current."""
    h = hashlib.sha256()
    for f in sorted(files, key=lambda f: f.name):
        h.update(f"{f.name}\0".encode())
        h.update(hashlib.sha256(f.read_bytes()).digest())
    code = [sys.modules[__name__]] + [
        importlib.import_module(n) for m in mods for n in getattr(m, "CODE", ())
    ]
    for m in mods + code:
        h.update(Path(m.__file__).read_bytes())
    return h.hexdigest()


def _data_files(folder: Path, mods) -> list[Path]:
    """The files the figure modules read in ``folder`` (their ``inputs(folder)``, else their
    ``DATA`` globs): what a stamp hashes, and nothing else."""
    files = set()
    for m in mods:
        files |= (
            set(m.inputs(folder))
            if hasattr(m, "inputs")
            else {f for g in m.DATA for f in folder.glob(g)}
        )
    return sorted(f for f in files if f.is_file())


def _stamped(folder: Path, mods, redraw: bool) -> list[Path]:
    """Each module's figures of ``folder``, redrawn only when its stamp (the data it reads
    and its code) differs from the one recorded in the folder's STAMP file with the PNGs it
    drew; the file is rewritten only when something changed (byte-identical otherwise)."""

    sfile = folder / STAMP
    try:
        old = json.loads(sfile.read_text()) if sfile.exists() else {}
        old = old if isinstance(old, dict) else {}
    except (OSError, ValueError):
        old = {}
    new, out = {}, []
    for m in mods:
        stamp = _stamp(_data_files(folder, [m]), [m])
        prev = old.get(m.NAME)
        pngs = None
        if not redraw and isinstance(prev, dict) and prev.get("stamp") == stamp:
            pngs = [folder / n for n in prev.get("pngs", [])]
            pngs = pngs if all(p.exists() for p in pngs) else None
        if pngs is None:
            pngs = _make([m], folder)
        new[m.NAME] = {"stamp": stamp, "pngs": sorted(p.name for p in pngs if p.parent == folder)}
        out += pngs
    write_changed(sfile, json.dumps(new, sort_keys=True, indent=1).encode())
    return out


def make_case_figures(folder, redraw: bool = False) -> list[Path]:
    """Figures of one case data folder; a kind is skipped (its existing PNGs returned) when
    the data it reads and its code are unchanged since its last drawing."""
    return _stamped(Path(folder), figure_modules("case"), redraw)


def make_suite_figures(suite_dir, redraw: bool = False) -> list[Path]:
    """The suite's figures (drawn from its summary.csv), skipped like a case's."""
    return _stamped(Path(suite_dir), figure_modules("suite"), redraw)


def make_bench_figures(bench_dir, redraw: bool = False) -> list[Path]:
    """The benchmarks' plot (drawn from the bench CSVs), skipped like a case's."""
    return _stamped(Path(bench_dir), figure_modules("bench"), redraw)


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_csv(folder: Path, name: str):
    """The data file ``folder/name`` as a DataFrame, or None if the stage did not write
    it (then the figure module draws nothing)."""
    src = Path(folder) / name
    if not src.exists():
        return None
    import pandas as pd

    return pd.read_csv(src)


def subplots(*args, **kwargs):
    """``plt.subplots`` on the Agg backend: (fig, axes)."""
    return pyplot().subplots(*args, **kwargs)


LENGTH_UNIT = "m"  # case files are in SI units (lengths m, stresses Pa, times s)


def title(folder: Path) -> str:
    """The case a data folder belongs to, for figure titles: ``case`` or ``case seed<N>``."""
    folder = Path(folder)
    return (
        f"{folder.parent.name} {folder.name}"
        if re.fullmatch(r"seed\d+", folder.name)
        else folder.name
    )


def log_if_decades(ax, values, axis: str = "y", decades: float = 1.5) -> bool:
    """Put ``axis`` on a log scale when the positive ``values`` span more than ``decades``
    decades (then small values stay readable beside large ones); True if it did."""
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    if not len(v) or (v <= 0).any() or v.max() / v.min() < 10**decades:
        return False
    (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
    return True


def save(fig, path: Path, tight: bool = True) -> Path:
    """Write ``fig`` as PNG (``tight``: tight_layout first, which draws the figure twice)."""
    if tight:
        fig.tight_layout()
    with staged([path]) as (tmp,):  # never half a PNG (disk full): the old one stays
        fig.savefig(tmp, dpi=100, format="png", metadata={"Software": None})
    return path
