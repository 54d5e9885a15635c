"""Relative volume variation against time (Bourguignon-Cani Fig. 3)."""

from __future__ import annotations

from pathlib import Path

from harness.figures import read_csv, save, subplots

NAME, SCOPE = "volume", "case"


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "volume.csv")
    if df is None:
        return []
    fig, ax = subplots(figsize=(6, 4))
    for col in df.columns:
        if col != "t":
            ax.plot(df["t"], df[col], lw=1.2, label=col)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("volume variation (%)")
    ax.set_title(f"{folder.name}: volume variation")
    ax.legend()
    return [save(fig, folder / "fig-volume.png")]
