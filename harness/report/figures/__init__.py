"""Figure registry: each figure kind is one module listed in ``FIGURES``.

A figure module has ``NAME``, ``SCOPE`` ("case": drawn per case data folder; "suite":
drawn once per suite folder from its summary.csv) and ``make(folder) -> list[Path]``,
which reads stored data files (formats in :mod:`harness.report.build`), writes PNGs into
``folder`` and returns their paths; no data file, no figure (an empty list). Figures
never recompute anything. A figure that fails is reported as one warning line and the
report carries on.
"""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

FIGURES = [
    "harness.report.figures.trace",        # G against SA steps (trace.csv)
    "harness.report.figures.lloyd",        # Lloyd statistics against iterations, Deussen Fig. 2 (lloyd.csv)
    "harness.report.figures.lloyd_bars",   # G per Lloyd iteration count, Deussen Fig. 12 (summary.csv)
    "harness.report.figures.volume",       # volume variation, Bourguignon-Cani Fig. 3 (volume.csv)
    "harness.report.figures.spectrum",     # natural frequencies model vs FEM (frequencies.csv)
    "harness.report.figures.anisotropy",   # polar plot of effective stiffness (anisotropy.csv)
    "harness.report.figures.deformed",     # reference vs model deformed shapes (deformed*.npz)
    "harness.report.figures.fibres",       # fibre fields, Bourguignon-Cani Fig. 6 (fibres.npz)
    "harness.report.figures.nu_sweep",     # G against Poisson's ratio per model class (summary.csv)
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
            print(f"springbench: warning: figure {m.NAME} in {folder}: {type(exc).__name__}: {exc}"
                  .replace("\n", " "), file=sys.stderr)
        finally:
            plt = sys.modules.get("matplotlib.pyplot")
            if plt is not None:
                plt.close("all")
    return out


STAMP = ".figures.json"


def _stamp(folder: Path, mods) -> str:
    """What a folder's figures depend on: its data files (name, size, mtime) and the
    figure code."""
    import hashlib
    h = hashlib.sha256()
    for f in sorted(folder.iterdir()):
        if f.is_file() and not f.name.startswith((".", "fig-")):
            st = f.stat()
            h.update(f"{f.name}\0{st.st_size}\0{st.st_mtime_ns}\0".encode())
    for m in mods + [sys.modules[__name__]]:
        h.update(Path(m.__file__).read_bytes())
    return h.hexdigest()


def make_case_figures(folder, redraw: bool = False) -> list[Path]:
    """Figures of one case data folder; skipped (the existing PNGs returned) when its
    data files and the figure code are unchanged since the last drawing."""
    import json
    folder = Path(folder)
    mods = figure_modules("case")
    stamp, sfile = _stamp(folder, mods), folder / STAMP
    if not redraw and sfile.exists():
        try:
            old = json.loads(sfile.read_text())
            pngs = [folder / n for n in old["pngs"]]
            if old["stamp"] == stamp and all(p.exists() for p in pngs):
                return pngs
        except (ValueError, KeyError, TypeError):
            pass
    out = _make(mods, folder)
    sfile.write_text(json.dumps({"stamp": stamp, "pngs": [p.name for p in out if p.parent == folder]}))
    return out


def make_suite_figures(suite_dir) -> list[Path]:
    return _make(figure_modules("suite"), suite_dir)


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


LENGTH_UNIT = "m"   # case files are in SI units (lengths m, stresses Pa, times s)


def title(folder: Path) -> str:
    """The case a data folder belongs to, for figure titles: ``case`` or ``case seed<N>``."""
    folder = Path(folder)
    return f"{folder.parent.name} {folder.name}" if re.fullmatch(r"seed\d+", folder.name) else folder.name


def log_if_decades(ax, values, axis: str = "y", decades: float = 1.5) -> bool:
    """Put ``axis`` on a log scale when the positive ``values`` span more than ``decades``
    decades (then small values stay readable beside large ones); True if it did."""
    import numpy as np
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    if not len(v) or (v <= 0).any() or v.max() / v.min() < 10 ** decades:
        return False
    (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
    return True


def save(fig, path: Path, tight: bool = True) -> Path:
    """Write ``fig`` as PNG (``tight``: tight_layout first, which draws the figure twice)."""
    from harness.outputs import staged
    if tight:
        fig.tight_layout()
    with staged([path]) as (tmp,):     # never half a PNG (disk full): the old one stays
        fig.savefig(tmp, dpi=100, format="png", metadata={"Software": None})
    return path
