"""The benchmarks' plot (results/bench/reference.csv): left, the FEM solve's seconds against
its unknowns per element and solver; right, the reference's true error against its
unknowns per method (against an independent finer solve). Log axes."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import read_csv, save, subplots

NAME, SCOPE = "bench_reference", "bench"
DATA = ("reference.csv",)  # the files it reads (globs in the folder): its figures' stamp


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "reference.csv")
    if df is None or not {"task", "n_dofs", "seconds"} <= set(df.columns):
        return []
    fig, (left, right) = subplots(1, 2, figsize=(11, 4.5))
    solve = df[df["task"] == "solve"]
    for (element, solver), g in solve.groupby(["element", "solver"], sort=True):
        g = g.sort_values("n_dofs")
        left.plot(g["n_dofs"], g["seconds"], "o-", ms=3, lw=1, label=f"{element}, {solver}")
    left.set(
        xscale="log",
        yscale="log",
        xlabel="unknowns (dofs)",
        ylabel="solve time (s)",
        title="FEM solve time",
    )
    acc = df[(df["task"] == "accuracy")] if "true_error" in df else df.iloc[:0]
    acc = acc[acc["true_error"].notna() & (acc["true_error"] > 0)] if len(acc) else acc
    for method, g in acc.groupby("method", sort=True):
        g = g.sort_values("n_dofs").drop_duplicates("n_dofs")
        right.plot(g["n_dofs"], g["true_error"], "o-", ms=3, lw=1, label=str(method))
    right.set(
        xscale="log",
        yscale="log",
        xlabel="unknowns (dofs)",
        ylabel="true error / largest displacement",
        title="FEM reference error against an independent solve",
    )
    for ax in (left, right):
        ax.grid(True, which="major", lw=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    return [save(fig, folder / "fig-bench-reference.png")]
