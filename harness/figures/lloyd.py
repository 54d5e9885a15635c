"""Lloyd statistics against iterations (Deussen Fig. 2): standard deviations of
neighbour distances and of region sizes."""

from __future__ import annotations

from pathlib import Path

from harness.figures import pyplot, save

NAME, SCOPE = "lloyd", "case"


def make(folder: Path) -> list[Path]:
    src = folder / "lloyd.csv"
    if not src.exists():
        return []
    import pandas as pd
    df = pd.read_csv(src)
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.2))
    for ax, col, label in zip(axes, ("std_distance", "std_area"),
                              ("std of neighbour distances", "std of region sizes")):
        if col in df:
            ax.plot(df["iteration"], df[col], "o-", ms=3)
        ax.set_xlabel("Lloyd iterations")
        ax.set_title(label, fontsize=9)
    fig.suptitle(folder.name, fontsize=9)
    return [save(fig, folder / "fig-lloyd.png")]
