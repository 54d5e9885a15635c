"""The engine table's numbers that docs/engines.md and README.md cite, from a summary.csv
of the engines suite: python .rerun/table_numbers.py results/engines/summary.csv"""

import sys

import numpy as np
import pandas as pd

d = pd.read_csv(sys.argv[1])
d["who"] = (
    d.engine + ": " + d.model.str.replace(r"springbench ([\w-]+):.*", r"springbench \1", regex=True)
)
m = d[d.load == "mean"]
print(f"{d.case.nunique()} cases, {len(d[d.load != 'mean'])} engine runs (loads), statuses:")
print(d[d.load != "mean"].engine_status.value_counts().to_string())
bad = d[(d.load != "mean") & ~d.engine_status.isin(["settled", "unsupported-load"])]
print(
    "not settled:",
    bad[["case", "who", "load", "engine_status", "note"]].to_string() if len(bad) else "none",
)
print("\nmean G_norm over the held-out loads, range per nu:")
for who, g in m.groupby("who"):
    per = {nu: (h.G_norm.min(), h.G_norm.max()) for nu, h in g.groupby("nu")}
    print(f"  {who}: " + "; ".join(f"nu {nu}: {a:.3g}-{b:.3g}" for nu, (a, b) in per.items()))
own = m[m.model == "own (E, nu)"].pivot_table(index="case", columns="engine", values="G_norm")
print(
    "\nnewton-tets vs mujoco-flex own, max relative gap of the means:",
    f"{np.nanmax(np.abs(own['newton-tets'] / own['mujoco-flex'] - 1)):.2%}",
)
runs = d[d.load != "mean"].pivot_table(
    index=["case", "load", "model"], columns="engine", values="G_norm"
)
both = runs[["newton-tets", "mujoco-flex"]].dropna()
print("  per load:", f"{np.max(np.abs(both['newton-tets'] / both['mujoco-flex'] - 1)):.2%}")


def ratio(a, b, engine):
    x = m[(m.engine == engine)].pivot_table(index="case", columns="who", values="G_norm")
    r = x[a] / x[b]
    gm = np.exp(np.log(r).mean())
    return f"{a} / {b}: geomean {gm:.3g}, {r.min():.3g}-{r.max():.3g} over {r.notna().sum()} cases"


print()
print(
    ratio(
        "newton-springs: springbench calibrated",
        "newton-springs: springbench rule",
        "newton-springs",
    )
)
print(
    ratio(
        "mujoco-springs: springbench calibrated-mujoco",
        "mujoco-springs: springbench rule",
        "mujoco-springs",
    )
)
print(ratio("newton-tets: springbench p1-global", "newton-tets: own (E, nu)", "newton-tets"))
print(ratio("newton-tets: springbench p1", "newton-tets: own (E, nu)", "newton-tets"))
print(ratio("mujoco-flex: springbench p1-global", "mujoco-flex: own (E, nu)", "mujoco-flex"))
print("\nsteps and wall time per engine (settled runs):")
s = d[(d.load != "mean") & (d.engine_status == "settled")]
for (e, who), g in s.groupby(["engine", "who"]):
    print(
        f"  {who}: {len(g)} runs, at most {g.steps.max():.0f} steps, {g.wall_s.sum():.0f} s in all"
    )
