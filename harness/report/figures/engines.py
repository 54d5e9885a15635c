"""The engine table's plot (the engines suite's summary.csv; the bench's engines.csv draws
the same): per body, each engine's mean G_norm over the held-out loads against nu, coarse
mesh dashed, fine solid; log y; a colour per engine and model, a marker per engine. Runs
that found no equilibrium are left out."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

from harness.report.figures import read_csv, save, subplots

NAME, SCOPE = "engines", "suite"
MARKERS = "os^Dvp"  # one per engine; the colour tells engine and model apart
LEGEND_ROW = 0.2  # inches per row of the legend below the panels
DATA = ("summary.csv",)
NEED = {"body", "resolution", "n_tets", "nu", "engine", "model", "load", "G_norm"}


def who(model_column):
    """'engine: model' labels with the export's detail dropped ('springbench rule: rule
    learned' -> 'springbench rule')."""
    return model_column.str.replace(r"springbench ([\w-]+):.*", r"springbench \1", regex=True)


def draw(df, out: Path) -> list[Path]:
    if df is None or not NEED <= set(df.columns):
        return []
    m = df[(df["load"] == "mean") & df["G_norm"].notna()].copy()
    if m.empty:
        return []
    m["who"] = m["engine"] + ": " + who(m["model"])
    bodies = list(dict.fromkeys(m["body"]))
    series = list(dict.fromkeys(m["who"]))
    ncol = max(3, len(bodies))
    rows = math.ceil((len(series) + 2) / ncol)  # the legend's rows: series and two line styles
    height = 3.8 + LEGEND_ROW * rows
    fig, axes = subplots(1, len(bodies), figsize=(4.2 * len(bodies), height), squeeze=False)
    palette = matplotlib.colormaps["tab20"]  # ten colours repeat from the 11th series on
    colours = {w: palette(i % palette.N) for i, w in enumerate(series)}
    engines = list(dict.fromkeys(m["engine"]))
    markers = {e: MARKERS[i % len(MARKERS)] for i, e in enumerate(engines)}
    marker = dict(zip(m["who"], m["engine"].map(markers)))
    for ax, body in zip(axes[0], bodies):
        b = m[m["body"] == body]
        tets = {r: int(g["n_tets"].iloc[0]) for r, g in b.groupby("resolution", sort=False)}
        for (label, res), g in b.groupby(["who", "resolution"], sort=False):
            g = g.sort_values("nu")
            ax.plot(
                g["nu"],
                g["G_norm"],
                marker[label] + ("-" if res == "fine" else "--"),
                ms=3,
                lw=1,
                color=colours[label],
            )
        ax.set(
            yscale="log",
            xlabel="Poisson's ratio nu",
            ylabel="mean G_norm over the held-out loads",
            title=f"{body} (" + ", ".join(f"{r} {n} tets" for r, n in tets.items()) + ")",
        )
        ax.grid(True, which="major", lw=0.3)
    handles = [
        axes[0][0].plot([], [], marker[w] + "-", ms=3, lw=1, color=c, label=w)[0]
        for w, c in colours.items()
    ]
    handles += [
        axes[0][0].plot([], [], ls, color="grey", lw=1, label=f"{res} mesh")[0]
        for ls, res in (("--", "coarse"), ("-", "fine"))
    ]
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, (LEGEND_ROW * rows + 0.15) / height, 1, 1))
    return [save(fig, out, tight=False)]


def make(folder: Path) -> list[Path]:
    return draw(read_csv(folder, "summary.csv"), Path(folder) / "fig-engines.png")
