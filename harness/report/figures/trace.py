"""G against optimiser steps (optimiser trace), one line per model; log axes."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import LENGTH_UNIT, read_csv, save, subplots, title

NAME, SCOPE = "trace", "case"
DATA = ("trace.csv",)  # the files it reads (globs in the folder): its figures' stamp


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "trace.csv")
    if df is None:
        return []
    fig, ax = subplots(figsize=(9, 4.5))
    groups = df.groupby("model", sort=True) if "model" in df else [("", df)]
    for model, g in groups:
        ax.plot(g["step"], g["G"], lw=0.9, label=f"{model} G".strip())
        if "G_best" in g:
            ax.plot(g["step"], g["G_best"], lw=1.4, label=f"{model} best".strip())
    if (df["G"] > 0).all():
        ax.set_yscale("log")
    if "model" in df and df["model"].nunique() > 1 and df["step"].max() > 10:
        # SA takes thousands of proposals, a gradient fit tens of evaluations: log steps
        ax.set_xscale("symlog", linthresh=1)
        ax.set_xlim(left=0)
        ax.set_xlabel(
            "step (SA proposals, L-BFGS-B / Nelder-Mead evaluations, Gauss-Newton iterations)"
        )
    else:
        ax.set_xlabel("step")
    ax.set_ylabel(f"G (weighted root-sum-square displacement error, {LENGTH_UNIT})")
    ax.grid(True, which="major", lw=0.3)
    ax.set_title(f"{title(folder)}: G against optimiser steps")
    ax.legend(fontsize=8)
    return [save(fig, folder / "fig-trace.png")]
