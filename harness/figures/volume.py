"""Relative volume variation against time (Bourguignon-Cani Fig. 3)."""

from __future__ import annotations

from pathlib import Path

from harness.figures import pyplot, save

NAME, SCOPE = "volume", "case"


def make(folder: Path) -> list[Path]:
    src = folder / "volume.csv"
    if not src.exists():
        return []
    import pandas as pd
    df = pd.read_csv(src)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    for col in df.columns:
        if col != "t":
            ax.plot(df["t"], df[col], lw=1.2, label=col)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("volume variation (%)")
    ax.set_title(f"{folder.name}: volume variation")
    ax.legend()
    return [save(fig, folder / "fig-volume.png")]
