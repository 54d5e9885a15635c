"""Natural frequencies of the models against the FEM reference, per mode."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import log_if_decades, read_csv, save, subplots, title

NAME, SCOPE = "spectrum", "case"
DATA = ("frequencies.csv",)  # the files it reads (globs in the folder): its figures' stamp


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "frequencies.csv")
    if df is None:
        return []
    fig, ax = subplots(figsize=(9, 4.5))
    modes = df["mode"] if "mode" in df else range(1, len(df) + 1)
    if "fem" in df:
        ax.plot(modes, df["fem"], "ks-", label="FEM", ms=5)
    for col in df.columns:
        if col not in ("mode", "fem"):
            ax.plot(modes, df[col], "o--", label=col, ms=4)
    log_if_decades(ax, df[[c for c in df.columns if c != "mode"]].to_numpy(float))
    ax.set_xlabel("mode number")
    if len(df) <= 20:
        ax.set_xticks(list(modes))
    ax.set_ylabel("natural frequency (Hz)")
    ax.grid(True, lw=0.3)
    ax.set_title(f"{title(folder)}: natural frequencies, models (dashed) against the FEM (black)")
    ax.legend(fontsize=8, ncol=2)
    return [save(fig, folder / "fig-spectrum.png")]
