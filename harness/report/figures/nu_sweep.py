"""The nu-sweep map (issue #15): normalised G against Poisson's ratio, one panel per body,
one colour per model class (solid: the fitted loads' G_norm, dashed: G_heldout on the loads
no fit saw), log scale (values below FLOOR drawn at it), the Cauchy ratio of central-spring lattices marked (1/4 in 3-D,
1/3 in 2-D plane stress). Rows from summary.csv through harness.report.nu_sweep."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import read_csv, save, subplots

NAME, SCOPE = "nu_sweep", "suite"
FLOOR = 1e-6    # G below this (P1 on a linear field: exact to rounding) is drawn at it


def make(folder: Path) -> list[Path]:
    from harness.report.nu_sweep import CAUCHY_NU, sweep_frame
    df = read_csv(folder, "summary.csv")
    if df is None:
        return []
    frame = sweep_frame(df)
    if frame.empty or frame["nu"].nunique() < 2:
        return []
    bodies = list(dict.fromkeys(frame["body"]))
    classes = list(dict.fromkeys(frame["model_class"]))
    fig, axes = subplots(1, len(bodies), figsize=(4.2 * len(bodies), 3.8), squeeze=False)
    for ax, body in zip(axes[0], bodies):
        b = frame[frame["body"] == body]
        for i, cls in enumerate(classes):
            c = b[b["model_class"] == cls].sort_values("nu")
            if c.empty:
                continue
            colour = f"C{i}"
            ax.plot(c["nu"], c["G_norm_final"].clip(lower=FLOOR), "o-", color=colour, label=f"{cls} (fitted loads)")
            if "G_heldout" in c and c["G_heldout"].notna().any():
                ax.plot(c["nu"], c["G_heldout"].clip(lower=FLOOR), "s--", color=colour, mfc="none", label=f"{cls} (held out)")
        dim = int(b["dim"].iloc[0]) if "dim" in b and b["dim"].notna().any() else 3
        ax.axvline(CAUCHY_NU[dim], color="k", ls=":", lw=1)
        ax.text(CAUCHY_NU[dim], 0.98, f" Cauchy nu = {'1/4' if dim == 3 else '1/3'}", transform=ax.get_xaxis_transform(),
                fontsize=7, va="top")
        ax.set_yscale("log")
        ax.set_xlabel("Poisson's ratio nu")
        ax.set_ylabel("normalised G (RMS error / RMS displacement)")
        ax.set_title(body, fontsize=9)
    axes[0][0].legend(fontsize=6)
    fig.suptitle(f"{folder.name}: how close each model class gets to the FEM, per nu "
                 f"(G < {FLOOR:g}, exact to rounding, drawn at {FLOOR:g})", fontsize=10)
    return [save(fig, folder / "fig-nu-sweep.png")]
