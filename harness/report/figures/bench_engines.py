"""The engine table's plot (results/bench/engines.csv): per body, each engine's mean G_norm
over the held-out loads against nu, coarse mesh dashed, fine solid; log y."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import read_csv, save, subplots

NAME, SCOPE = "bench_engines", "bench"
DATA = ("engines.csv",)


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "engines.csv")
    if df is None or not {"body", "nu", "engine", "model", "load", "G_norm"} <= set(df.columns):
        return []
    m = df[(df["load"] == "mean") & df["G_norm"].notna()].copy()
    if m.empty:
        return []
    m["who"] = m["engine"] + ": " + m["model"].str.replace(r"springbench (\w+):.*", r"springbench \1", regex=True)
    bodies = list(dict.fromkeys(m["body"]))
    fig, axes = subplots(1, len(bodies), figsize=(4.2 * len(bodies), 4.2), squeeze=False)
    colours = {w: f"C{i}" for i, w in enumerate(dict.fromkeys(m["who"]))}
    for ax, body in zip(axes[0], bodies):
        for (who, res), g in m[m["body"] == body].groupby(["who", "resolution"], sort=False):
            g = g.sort_values("nu")
            ax.plot(g["nu"], g["G_norm"], "o-" if res == "fine" else "o--", ms=3, lw=1, color=colours[who],
                    label=f"{who} ({res}, {int(g['n_tets'].iloc[0])} tets)")
        ax.set(yscale="log", xlabel="Poisson's ratio nu", ylabel="mean G_norm over the held-out loads", title=body)
        ax.grid(True, which="major", lw=0.3)
        ax.legend(fontsize=6)
    return [save(fig, folder / "fig-bench-engines.png")]
