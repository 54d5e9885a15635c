"""Relative volume variation against time (Bourguignon-Cani Fig. 3), ours solid and, where
the case names the original program's record (``[dynamics] original``), the program's curve
dashed on top, with our difference from it in a second panel (read from that data file,
nothing recomputed)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from harness.report.figures import read_csv, save, subplots, title

NAME, SCOPE = "volume", "case"
DATA = ("volume.csv",)  # the files it reads (globs in the folder): its figures' stamp
MODELS = ("MS", "MT0", "MT")


def original_record(folder: Path) -> Path | None:
    """The original program's record (``[dynamics] original``) named by the case file of the
    first stored result in ``folder``; None when there is none or it cannot be found."""
    manifests = sorted(folder.glob("result-seed*.json")) or sorted(
        folder.parent.glob("result-seed*.json")
    )
    for m in manifests[:1]:
        try:
            case = Path(json.loads(m.read_text())["file"])
            if not case.is_file():  # results moved: the checkout's own cases/<suite>/
                case = m.parents[2].parent / "cases" / m.parents[1].name / case.name
            import tomllib

            name = tomllib.loads(case.read_text()).get("dynamics", {}).get("original")
        except (OSError, ValueError, KeyError, TypeError, IndexError):
            return None
        return case.parent / name if name and (case.parent / name).is_file() else None
    return None


def inputs(folder: Path) -> list[Path]:
    """What the figure reads: volume.csv and the original program's record."""
    rec = original_record(folder) if (folder / "volume.csv").exists() else None
    return [folder / "volume.csv"] + ([rec] if rec is not None else [])


def original_curves(folder: Path) -> dict:
    """{model: (t, dV/V0 %)} of the original program's record (:func:`original_record`; its
    column rule is the bc2000 stage's: t, MS, MT0, MT, or t, V, dV/V0 % for one model); {}
    when there is none or it cannot be read."""
    rec = original_record(folder)
    if rec is None:
        return {}
    try:
        ref = np.loadtxt(rec, skiprows=1, ndmin=2)
    except (OSError, ValueError):
        return {}
    if ref.shape[1] == 4:
        return {n: (ref[:, 0], ref[:, i + 1]) for i, n in enumerate(MODELS)}
    return {"*": (ref[:, 0], ref[:, 2])} if ref.shape[1] >= 3 else {}


def deviations(df, orig: dict) -> dict:
    """{model: (t, original, ours - original)} at the record's times, ours interpolated there (the
    record starts at t = dt, ours at 0); a one-model record ("*") goes to our one model."""
    cols = [c for c in df.columns if c != "t"]
    if "*" in orig:
        orig = {cols[0]: orig["*"]} if len(cols) == 1 else {}
    return {c: (t, v, np.interp(t, df["t"], df[c]) - v) for c, (t, v) in orig.items() if c in cols}


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "volume.csv")
    if df is None:
        return []
    dev = deviations(df, original_curves(folder))
    cols = [c for c in df.columns if c != "t"]
    fig, axes = subplots(
        2 if dev else 1,
        1,
        figsize=(9, 6.5 if dev else 4.5),
        squeeze=False,
        sharex=True,
        gridspec_kw={"height_ratios": [3, 1.3]} if dev else None,
    )
    ax = axes[0, 0]
    for i, col in enumerate(cols):
        ax.plot(df["t"], df[col], lw=1.6, color=f"C{i}", label=f"{col} (ours)")
    for i, (col, (t, v, d)) in enumerate(dev.items()):
        ax.plot(t, v, lw=1.2, color="k", dashes=(4, 3), label=None if i else "original program")
        axes[1, 0].plot(t, d, lw=1, color=f"C{cols.index(col)}", label=col)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_ylabel("volume variation 100 (V - V0) / V0 (%)")
    ax.set_title(
        f"{title(folder)}: volume variation"
        + (", ours vs the original program (dashed)" if dev else "")
    )
    ax.legend(fontsize=8)
    ax.grid(True, lw=0.3)
    if dev:
        b = axes[1, 0]
        b.set_ylabel("ours - original (%)", fontsize=9)
        b.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
        b.grid(True, lw=0.3)
        b.legend(fontsize=7, ncol=len(dev))
    axes[-1, 0].set_xlabel("t (s)")
    return [save(fig, folder / "fig-volume.png")]
