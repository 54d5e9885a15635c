"""The nu-sweep map, two figures from summary.csv through harness.report.nu_sweep, log
scales (values below FLOOR drawn at it):

- ``fig-nu-sweep.png``: normalised G against Poisson's ratio, one panel per body, one
  colour per model class (solid: the fitted loads' G_norm, dashed: G_heldout on the loads
  no fit saw), the Cauchy ratio of central-spring lattices marked (1/4 in 3-D, 1/3 in 2-D
  plane stress);
- ``fig-nu-sweep-families.png``: the held-out G per load family (columns: sag, tip,
  torsion, bridge) against nu, one row of panels per body: each class's fitted row solid,
  each unfitted stiffness rule a dashed line of its own.
"""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import read_csv, save, subplots
from harness.report.nu_sweep import CAUCHY_NU, families_of, family_frame, sweep_frame

NAME, SCOPE = "nu_sweep", "suite"
DATA = ("summary.csv",)  # the files it reads (globs in the folder): its figures' stamp
CODE = ("harness.report.nu_sweep",)  # the other code its figures depend on
FLOOR = 1e-6  # G below this (P1 on a linear field: exact to rounding) is drawn at it
RULE_COLOURS = ("tab:gray", "tab:brown", "tab:olive", "tab:cyan", "tab:pink", "black")


def make(folder: Path) -> list[Path]:
    df = read_csv(folder, "summary.csv")
    if df is None:
        return []
    out = []
    frame = sweep_frame(df)
    if not frame.empty and frame["nu"].nunique() >= 2:
        out.append(_classes(folder, frame))
    fam = family_frame(df)
    if not fam.empty and fam["nu"].nunique() >= 2:
        out.append(_families(folder, fam))
    return out


def _cauchy(ax, dim: int) -> None:
    ax.axvline(CAUCHY_NU[dim], color="k", ls=":", lw=1)
    ax.text(
        CAUCHY_NU[dim],
        0.98,
        f" Cauchy nu = {'1/4' if dim == 3 else '1/3'}",
        transform=ax.get_xaxis_transform(),
        fontsize=7,
        va="top",
    )


def _dim(b) -> int:
    return int(b["dim"].dropna().iloc[0]) if "dim" in b and b["dim"].notna().any() else 3


def _classes(folder: Path, frame) -> Path:
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
            ax.plot(
                c["nu"],
                c["G_norm_final"].clip(lower=FLOOR),
                "o-",
                color=colour,
                label=f"{cls} (fitted loads)",
            )
            if "G_heldout" in c and c["G_heldout"].notna().any():
                ax.plot(
                    c["nu"],
                    c["G_heldout"].clip(lower=FLOOR),
                    "s--",
                    color=colour,
                    mfc="none",
                    label=f"{cls} (held out)",
                )
        _cauchy(ax, _dim(b))
        ax.set_yscale("log")
        ax.set_xlabel("Poisson's ratio nu")
        ax.set_ylabel("normalised G (RMS error / RMS displacement)")
        ax.set_title(body, fontsize=9)
    axes[0][0].legend(fontsize=6)
    fig.suptitle(
        f"{folder.name}: how close each model class gets to the FEM, per nu "
        f"(G < {FLOOR:g}, exact to rounding, drawn at {FLOOR:g})",
        fontsize=10,
    )
    return save(fig, folder / "fig-nu-sweep.png")


def _families(folder: Path, frame) -> Path:
    bodies = list(dict.fromkeys(frame["body"]))
    fams = families_of(frame)
    models = list(dict.fromkeys(frame["model"]))
    classes = [m for m in models if not m.startswith("rule: ")]
    style = {
        m: dict(color=f"C{i}", ls="-", marker="o", lw=1.6, ms=4) for i, m in enumerate(classes)
    }
    style.update(
        {
            m: dict(color=RULE_COLOURS[i % len(RULE_COLOURS)], ls="--", marker="x", lw=1.0, ms=4)
            for i, m in enumerate(m for m in models if m.startswith("rule: "))
        }
    )
    legend = 0.35 + 0.2 * ((len(models) + 4) // 5)  # inches under the panels for the legend's rows
    height = 2.9 * len(bodies) + legend + 0.4
    fig, axes = subplots(len(bodies), len(fams), figsize=(3.4 * len(fams), height), squeeze=False)
    for r, body in enumerate(bodies):
        b = frame[frame["body"] == body]
        for c, fam in enumerate(fams):
            ax = axes[r][c]
            if not b[fam].notna().any():
                ax.axis("off")
                ax.text(
                    0.5,
                    0.5,
                    f"{body}: no {fam} load",
                    ha="center",
                    va="center",
                    fontsize=8,
                    transform=ax.transAxes,
                )
                continue
            for m in models:
                s = b[b["model"] == m].sort_values("nu")
                if s[fam].notna().any():
                    ax.plot(s["nu"], s[fam].clip(lower=FLOOR), label=m, **style[m])
            _cauchy(ax, _dim(b))
            ax.set_yscale("log")
            ax.set_title(f"{body}: {fam}", fontsize=9)
            if r == len(bodies) - 1:
                ax.set_xlabel("Poisson's ratio nu")
            if c == 0:
                ax.set_ylabel("held-out normalised G")
    handles = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    labels = list(handles)
    fig.legend(
        [handles[k] for k in labels],
        labels,
        loc="lower center",
        ncol=min(len(labels), 5),
        fontsize=7,
    )
    fig.suptitle(
        f"{folder.name}: held-out G per load family (never fitted, never used to choose); classes "
        "solid (their fitted rows), the unfitted stiffness rules dashed",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, legend / height, 1, 1 - 0.4 / height))
    return save(fig, folder / "fig-nu-sweep-families.png", tight=False)
