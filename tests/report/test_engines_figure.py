"""The engine table's plot (harness/report/figures/engines.py) with as many series as the
suite draws (eleven engine-and-model pairs on two bodies): every series has its own colour
and marker, and the legend below the panels overlaps neither them nor their axis labels."""

import pandas as pd
import pytest
from matplotlib.colors import to_rgba

from harness.report.figures import engines as F

ENGINES = {
    "newton-tets": ("own (E, nu)", "springbench p1-global: E", "springbench p1: x"),
    "mujoco-flex": ("own (E, nu)", "springbench p1-global: E"),
    "pybullet-fem": ("own (E, nu)",),
    "drake-fem": ("own (E, nu)",),
    "newton-springs": ("springbench rule: rule learned", "springbench calibrated: fit"),
    "mujoco-springs": ("springbench rule: rule learned", "springbench calibrated-mujoco: fit"),
}


def _summary() -> pd.DataFrame:
    rows = []
    for i, (engine, models) in enumerate(ENGINES.items()):
        for j, model in enumerate(models):
            for body, res, n in (("beam", "coarse", 460), ("elbow", "fine", 2377)):
                for nu in (0.3, 0.45, 0.49):
                    g = 0.05 * (1 + i) * (1 + j) * (1 + nu)
                    rows.append(dict(body=body, resolution=res, n_tets=n, nu=nu, engine=engine))
                    rows[-1].update(model=model, load="mean", G_norm=g)
    return pd.DataFrame(rows)


def test_every_series_is_told_apart_and_the_legend_overlaps_nothing(tmp_path, monkeypatch):
    figs = []
    monkeypatch.setattr(F, "save", lambda fig, out, tight=True: figs.append(fig) or out)
    F.draw(_summary(), tmp_path / "fig-engines.png")
    (fig,) = figs
    styles = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            if len(line.get_xdata()):
                styles.setdefault((to_rgba(line.get_color()), line.get_marker()), set()).add(
                    line.get_ydata()[0]
                )
    assert len(styles) == sum(len(m) for m in ENGINES.values()) == 11
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legend = fig.legends[0].get_window_extent(renderer)
    for ax in fig.axes:
        box = ax.get_tightbbox(renderer)  # the panel with its tick and axis labels
        assert legend.y1 < box.y0, (legend, box)
    assert legend.y0 >= 0 and len(fig.legends[0].get_texts()) == 13


@pytest.mark.parametrize("n_bodies", [1, 4])
def test_the_figure_is_drawn_for_any_number_of_bodies(tmp_path, monkeypatch, n_bodies):
    figs = []
    monkeypatch.setattr(F, "save", lambda fig, out, tight=True: figs.append(fig) or out)
    df = _summary()
    df["body"] = [f"b{k % n_bodies}" for k in range(len(df))]
    F.draw(df, tmp_path / "fig-engines.png")
    assert len(figs[0].axes) == n_bodies
