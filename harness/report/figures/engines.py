"""The engine table's plot (the engines suite's summary.csv; the bench's engines.csv draws
the same): per body, each engine's mean G_norm over the held-out loads against nu, coarse
mesh dashed, fine solid; log y. Runs that found no equilibrium are left out."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import read_csv, save, subplots

NAME, SCOPE = "engines", "suite"
DATA = ("summary.csv",)
NEED = {"body", "resolution", "n_tets", "nu", "engine", "model", "load", "G_norm"}


def who(model_column):
    """'engine: model' labels with the export's detail dropped ('springbench rule: rule
    learned' -> 'springbench rule')."""
    return model_column.str.replace(r"springbench ([\w-]+):.*", r"springbench \1", regex=True)


def draw(df, out: Path) -> list[Path]:
    if df is None or not NEED <= set(df.columns):
        return []
    m = df[(df["load"] == "mean") & df["G_norm"].notna()].copy()
    if m.empty:
        return []
    m["who"] = m["engine"] + ": " + who(m["model"])
    bodies = list(dict.fromkeys(m["body"]))
    fig, axes = subplots(1, len(bodies), figsize=(4.2 * len(bodies), 4.6), squeeze=False)
    colours = {w: f"C{i}" for i, w in enumerate(dict.fromkeys(m["who"]))}
    for ax, body in zip(axes[0], bodies):
        b = m[m["body"] == body]
        tets = {r: int(g["n_tets"].iloc[0]) for r, g in b.groupby("resolution", sort=False)}
        for (label, res), g in b.groupby(["who", "resolution"], sort=False):
            g = g.sort_values("nu")
            ax.plot(
                g["nu"],
                g["G_norm"],
                "o-" if res == "fine" else "o--",
                ms=3,
                lw=1,
                color=colours[label],
            )
        ax.set(
            yscale="log",
            xlabel="Poisson's ratio nu",
            ylabel="mean G_norm over the held-out loads",
            title=f"{body} (" + ", ".join(f"{r} {n} tets" for r, n in tets.items()) + ")",
        )
        ax.grid(True, which="major", lw=0.3)
    handles = [
        axes[0][0].plot([], [], "o-", ms=3, lw=1, color=c, label=w)[0] for w, c in colours.items()
    ]
    handles += [
        axes[0][0].plot([], [], ls, color="grey", lw=1, label=f"{res} mesh")[0]
        for ls, res in (("--", "coarse"), ("-", "fine"))
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    return [save(fig, out, tight=False)]


def make(folder: Path) -> list[Path]:
    return draw(read_csv(folder, "summary.csv"), Path(folder) / "fig-engines.png")
