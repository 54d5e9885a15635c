"""Natural frequencies of the models against the FEM reference, per mode."""

from __future__ import annotations

from pathlib import Path

from harness.figures import read_csv, save, subplots

NAME, SCOPE = "spectrum", "case"


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "frequencies.csv")
    if df is None:
        return []
    fig, ax = subplots(figsize=(6, 4))
    modes = df["mode"] if "mode" in df else range(1, len(df) + 1)
    if "fem" in df:
        ax.plot(modes, df["fem"], "ks-", label="FEM", ms=5)
    for col in df.columns:
        if col not in ("mode", "fem"):
            ax.plot(modes, df[col], "o--", label=col, ms=4)
    ax.set_xlabel("mode")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(f"{folder.name}: natural frequencies")
    ax.legend(fontsize=8)
    return [save(fig, folder / "fig-spectrum.png")]
