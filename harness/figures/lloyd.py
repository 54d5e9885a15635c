"""Lloyd statistics against iterations (Deussen Fig. 2): standard deviations of
neighbour distances and of region sizes."""

from __future__ import annotations

from pathlib import Path

from harness.figures import read_csv, save, subplots

NAME, SCOPE = "lloyd", "case"


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "lloyd.csv")
    if df is None:
        return []
    fig, axes = subplots(1, 2, figsize=(8, 3.2))
    for ax, col, label in zip(axes, ("std_distance", "std_area"),
                              ("std of neighbour distances", "std of region sizes")):
        if col in df:
            ax.plot(df["iteration"], df[col], "o-", ms=3)
        ax.set_xlabel("Lloyd iterations")
        ax.set_title(label, fontsize=9)
    fig.suptitle(folder.name, fontsize=9)
    return [save(fig, folder / "fig-lloyd.png")]
