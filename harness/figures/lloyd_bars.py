"""G per Lloyd iteration count (Deussen Fig. 12) from the suite's summary.csv rows that
carry ``lloyd_iterations`` (the optimised rows if any): left, our G before and after
(mean and std over seeds); right, the trend G_final / G_final(fewest iterations), ours
beside the paper's (absolute G values are not comparable: the paper does not state units)."""

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
    if "optimizer" in df:  # optimised rows (G before -> after) if there are any
        opt = df[df["optimizer"].fillna("none") != "none"]
        df = opt if not opt.empty else df
    if df.empty:
        return []
    cols = [c for c in ("G_initial", "G_final") if c in df]
    g = df.groupby("lloyd_iterations")[cols + [c for c in ("paper_G_final",) if c in df]].agg(["mean", "std"])
    its = g.index.to_numpy()
    x = np.arange(len(its))
    plt = pyplot()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    w = 0.8 / len(cols)
    for i, c in enumerate(cols):
        ax.bar(x + (i - (len(cols) - 1) / 2) * w, g[(c, "mean")], w, yerr=g[(c, "std")].fillna(0),
               label=c, capsize=2)
    ax.set_title("ours: G before / after optimisation (mean, std over seeds)", fontsize=9)
    ax.set_ylabel("G")
    series = {"ours": g[("G_final", "mean")].to_numpy()}
    if ("paper_G_final", "mean") in g:
        series["paper"] = g[("paper_G_final", "mean")].to_numpy()
    w2 = 0.8 / len(series)
    for i, (name, v) in enumerate(series.items()):
        ax2.bar(x + (i - (len(series) - 1) / 2) * w2, v / v[0], w2, label=name)
    ax2.axhline(1, color="k", lw=0.5)
    ax2.set_title(f"trend: G_final / G_final at {int(its[0])} iterations", fontsize=9)
    for a in (ax, ax2):
        a.set_xticks(x, [f"{int(v)}" for v in its])
        a.set_xlabel("Lloyd iterations")
        a.legend(fontsize=8)
    fig.suptitle(f"{folder.name}: G per Lloyd iteration count (Deussen Fig. 12)", fontsize=10)
    return [save(fig, folder / "fig-lloyd-bars.png")]
