"""G per Lloyd iteration count (Deussen Fig. 12) from the suite's summary.csv rows that
carry ``lloyd_iterations`` (the optimised rows if any, one bar per optimiser): left, our
G before and after (mean and std over seeds); right, the trend G_final / G_final(fewest
iterations), ours
beside the paper's (absolute G values are not comparable: the paper does not state units)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.report.figures import LENGTH_UNIT, log_if_decades, read_csv, save, subplots

NAME, SCOPE = "lloyd_bars", "suite"
DATA = ("summary.csv",)  # the files it reads (globs in the folder): its figures' stamp


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "summary.csv")
    if df is None:
        return []
    import pandas as pd

    if "lloyd_iterations" not in df or "G_final" not in df:
        return []
    df = df.dropna(subset=["lloyd_iterations", "G_final"])
    if "optimizer" in df:  # optimised rows (G before -> after) if there are any
        opt = df[df["optimizer"].fillna("none") != "none"]
        df = opt if not opt.empty else df
    if "objective" in df:  # the G-only fits (a frequency-term row answers another question)
        df = df[df["objective"].fillna("G") == "G"]
    if df.empty:
        return []
    # one bar per optimiser ([optimizer] compare runs several on the same models)
    methods = list(dict.fromkeys(df["optimizer"].fillna("none"))) if "optimizer" in df else ["none"]
    key = df["optimizer"].fillna("none") if "optimizer" in df else pd.Series("none", index=df.index)
    first = df[key == methods[0]]
    g = first.groupby("lloyd_iterations")[
        [c for c in ("G_initial", "G_final", "paper_G_final") if c in df]
    ].agg(["mean", "std"])
    its = g.index.to_numpy()
    label = {m: "" if len(methods) == 1 else f" {m}" for m in methods}
    bars = {"G_initial": g["G_initial"]} if "G_initial" in g else {}
    for m in methods:
        bars[f"G_final{label[m]}"] = (
            df[key == m].groupby("lloyd_iterations")["G_final"].agg(["mean", "std"]).reindex(its)
        )
    x = np.arange(len(its))
    fig, (ax, ax2) = subplots(1, 2, figsize=(10, 4))
    w = 0.8 / len(bars)
    for i, (c, v) in enumerate(bars.items()):
        ax.bar(
            x + (i - (len(bars) - 1) / 2) * w,
            v["mean"],
            w,
            yerr=v["std"].fillna(0),
            label=c,
            capsize=2,
        )
    if log_if_decades(ax, np.concatenate([v["mean"].to_numpy(float) for v in bars.values()])):
        # bars start below the data
        ax.set_ylim(bottom=0.5 * min(float(v["mean"].min()) for v in bars.values()))
    ax.set_title("ours: G before / after optimisation (mean, std over seeds)", fontsize=9)
    ax.set_ylabel(f"G ({LENGTH_UNIT})")
    series = {f"ours{label[m]}": bars[f"G_final{label[m]}"]["mean"].to_numpy() for m in methods}
    if ("paper_G_final", "mean") in g:
        series["paper"] = g[("paper_G_final", "mean")].to_numpy()
    w2 = 0.8 / len(series)
    for i, (name, v) in enumerate(series.items()):
        ax2.bar(x + (i - (len(series) - 1) / 2) * w2, v / v[0], w2, label=name)
    ax2.axhline(1, color="k", lw=0.5)
    ax2.set_title(f"trend: G_final / G_final at {int(its[0])} iterations", fontsize=9)
    ax2.set_ylabel(f"G_final / G_final at {int(its[0])} iterations (ratio)")
    for a in (ax, ax2):
        a.set_xticks(x, [f"{int(v)}" for v in its])
        a.set_xlabel("Lloyd iterations")
        a.legend(fontsize=8)
    fig.suptitle(f"{folder.name}: G per Lloyd iteration count (Deussen Fig. 12)", fontsize=10)
    return [save(fig, folder / "fig-lloyd-bars.png")]
