"""Reference vs model deformed shapes per load case, magnified (Deussen Fig. 8-11).
2-D: the springs drawn at rest (grey), the model's deformed network (blue) and the
reference displacement of the same nodes (red dots). 3-D: the same, projected on x-y."""

from __future__ import annotations

from pathlib import Path

from harness.figures import pyplot, save

NAME, SCOPE = "deformed", "case"


def _lines(ax, p, springs, **kw):
    from matplotlib.collections import LineCollection
    ax.add_collection(LineCollection(p[springs][:, :, :2], **kw))


def make(folder: Path) -> list[Path]:
    import numpy as np
    out = []
    for src in sorted(folder.glob("deformed*.npz")):
        suffix = src.stem[len("deformed"):]
        with np.load(src) as z:
            data = {k: z[k] for k in z.files}
        p = np.asarray(data["points"], float)
        springs = np.asarray(data["springs"], int) if "springs" in data else None
        loads = sorted(k[len("u_ref_"):] for k in data if k.startswith("u_ref_"))
        size = float(np.ptp(p, axis=0).max()) or 1.0
        plt = pyplot()
        for load in loads:
            u_ref = np.asarray(data[f"u_ref_{load}"], float)
            u = np.asarray(data.get(f"u_{load}", np.full_like(u_ref, np.nan)), float)
            umax = np.nanmax(np.abs(np.concatenate([u_ref, u]))) if np.isfinite(u_ref).any() else 0
            scale = float(data["scale"]) if "scale" in data else (0.1 * size / umax if umax > 0 else 1.0)
            fig, ax = plt.subplots(figsize=(5, 5))
            if springs is not None and len(springs):
                _lines(ax, p, springs, colors="0.8", linewidths=0.6)
                if np.isfinite(u).all():
                    _lines(ax, p + scale * u, springs, colors="tab:blue", linewidths=0.9)
                    ax.plot([], [], color="tab:blue", label="model")
            elif np.isfinite(u).all():
                ax.plot(*(p + scale * u)[:, :2].T, "o", color="tab:blue", ms=3, label="model")
            ax.plot(*(p + scale * u_ref)[:, :2].T, ".", color="tab:red", ms=4, label="reference (FEM)")
            ax.set_aspect("equal")
            ax.autoscale()
            ax.set_title(f"{folder.name}{suffix}: {load} (x{scale:.3g})", fontsize=9)
            ax.legend(fontsize=7, loc="upper left")
            out.append(save(fig, folder / f"fig-deformed{suffix}-{load}.png"))
            plt.close(fig)
    return out
