"""Lloyd statistics against iterations (Deussen Fig. 2): standard deviations of
neighbour distances and of region sizes."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import LENGTH_UNIT, log_if_decades, read_csv, save, subplots, title

NAME, SCOPE = "lloyd", "case"
DATA = ("lloyd.csv",)  # the files it reads (globs in the folder): its figures' stamp


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "lloyd.csv")
    if df is None:
        return []
    fig, axes = subplots(1, 2, figsize=(10, 3.8))
    units = (LENGTH_UNIT, f"{LENGTH_UNIT}\u00b2 in 2-D, {LENGTH_UNIT}\u00b3 in 3-D")
    for ax, col, label, unit in zip(
        axes,
        ("std_distance", "std_area"),
        ("std of neighbour distances", "std of region sizes"),
        units,
    ):
        if col in df:
            ax.plot(df["iteration"], df[col], "o-", ms=3)
            log_if_decades(ax, df[col])
        ax.set_xlabel("Lloyd iterations")
        ax.set_ylabel(f"{label} ({unit})", fontsize=9)
        ax.grid(True, lw=0.3)
    fig.suptitle(f"{title(folder)}: Lloyd statistics (Deussen Fig. 2)", fontsize=10)
    return [save(fig, folder / "fig-lloyd.png")]
