"""G per Lloyd iteration count (Deussen Fig. 12): bars of G before/after optimisation
from the suite's summary.csv rows that carry ``lloyd_iterations``."""

from __future__ import annotations

from pathlib import Path

from harness.figures import pyplot, save

NAME, SCOPE = "lloyd_bars", "suite"


def make(folder: Path) -> list[Path]:
    src = folder / "summary.csv"
    if not src.exists():
        return []
    import numpy as np
    import pandas as pd
    df = pd.read_csv(src)
    if "lloyd_iterations" not in df or "G_final" not in df:
        return []
    df = df.dropna(subset=["lloyd_iterations", "G_final"])
    if df.empty:
        return []
    cols = [c for c in ("G_initial", "G_final", "paper_G_final") if c in df]
    g = df.groupby("lloyd_iterations")[cols].agg(["mean", "std"])
    its = g.index.to_numpy()
    x = np.arange(len(its))
    w = 0.8 / len(cols)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    for i, c in enumerate(cols):
        ax.bar(x + (i - (len(cols) - 1) / 2) * w, g[(c, "mean")], w,
               yerr=g[(c, "std")].fillna(0), label=c, capsize=2)
    ax.set_xticks(x, [f"{int(v)}" for v in its])
    ax.set_xlabel("Lloyd iterations")
    ax.set_ylabel("G")
    ax.set_title(f"{folder.name}: G per Lloyd iteration count (mean over seeds)")
    ax.legend(fontsize=8)
    return [save(fig, folder / "fig-lloyd-bars.png")]
