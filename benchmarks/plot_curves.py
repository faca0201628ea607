"""Charts of the staircase benchmark (from benchmarks/results/bench_staircase.json).

    .venv/bin/python benchmarks/plot_curves.py

docs/img/bench_staircase_curves.png: relative error (log) against the number of lights,
every method's curve, the NNLS solution as a point; negatives shown hollow.
docs/img/bench_staircase_time_error.png: each method's time to produce its curve (or
solution) against the error it reaches with <= 3 lights (positive) and at its best positive.
"""
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "benchmarks" / "results" / "bench_staircase.json"
IMG = ROOT / "docs" / "img"

STYLE = {
    "exitance-elimination x distance": ("C0", "-", 2.2, "exitance-elimination x distance (default)"),
    "exitance-elimination x local": ("C0", "--", 1.2, None),
    "exitance-elimination x coplanar": ("C0", ":", 1.2, None),
    "exitance-elimination x uniform": ("C0", "-.", 1.2, None),
    "exitance-elimination x distance (svd e_x)": ("C7", "-", 1.0, "exitance-elimination x distance, svd e_x"),
    "exitance-construction x distance": ("C1", "-", 1.5, None),
    "error-elimination x distance": ("C2", "-", 1.5, None),
    "error-construction x distance": ("C3", "-", 1.5, None),
    "nnls-greedy x none": ("C4", "-", 1.8, "nnls-greedy"),
}


def main():
    d = json.loads(DATA.read_text())
    IMG.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for name, c in d["curves"].items():
        color, ls, lw, label = STYLE.get(name, ("k", "-", 1, None))
        n = np.array(c["n_lights"])
        rel = np.maximum(np.array(c["relative_error"]), 1e-16)
        neg = np.array(c["n_negative"]) > 0
        steps = "" if c["selection"] != "error-construction" else " (30 steps)"
        ax.plot(n, rel, ls, color=color, lw=lw, label=(label or name) + steps)
        ax.plot(n[~neg], rel[~neg], ".", color=color, ms=2.5)
    nn = d["nnls_point"]
    ax.plot([nn["n_lights"]], [nn["relative_error"]], "*", color="C5", ms=13,
            label=f"NNLS solution ({nn['n_lights']} lights)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("number of lights")
    ax.set_ylabel("relative error  ||b_P - T e|| / ||b_P||  (Eq. 1)")
    ax.set_title(f"Staircase ({d['scene']['patches']} patches, {d['scene']['targets']} targets, "
                 f"{d['scene']['candidates']} candidates): error curves\n(dots: configurations with no "
                 "negative exitance)", fontsize=10)
    ax.axvline(3, color="0.6", lw=0.8)
    ax.set_ylim(1e-3, 3)
    ex = d["paper_points"]["reduced"]["e_x"]
    ax.annotate(f"e_x ({ex['n_lights']} lights): {ex['relative_error']:.1e}, below the chart",
                xy=(ex["n_lights"], 1e-3), xytext=(60, 1.6e-3), fontsize=8,
                arrowprops={"arrowstyle": "->", "color": "0.4"})
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7.5, loc="lower right")
    fig.tight_layout()
    fig.savefig(IMG / "bench_staircase_curves.png", dpi=110)
    plt.close(fig)

    # time to produce each curve (plus the solve that made its e_x) vs the error it reaches
    solve_t = {(r["solver"], r["driver"]): r["seconds"] for r in d["solves"]}
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for i, (name, c) in enumerate(d["curves"].items()):
        color, _, _, label = STYLE.get(name, ("k", "-", 1, None))
        t = c["seconds"] + (solve_t[("svd", "auto")] if c["e_x"] == "svd" else
                            (0.0 if c["selection"] == "nnls-greedy" else solve_t[("reduced", "auto")]))
        if c["selection"] == "nnls-greedy":
            t += solve_t[("reduced", "auto")]  # it needs T, built by the reduced solve's LU
        p3, pb = c["best_positive_le3"], c["best_positive"]
        marker = "os^vD<>ph"[i % 9]
        if p3:
            ax.plot([t], [p3["relative_error"]], marker, color=color, ms=8, label=f"{label or name}: <= 3 lights")
        if pb:
            ax.plot([t], [pb["relative_error"]], marker, color=color, ms=8, mfc="none",
                    label=f"   best positive ({pb['n_lights']} lights)")
    ax.plot([nn["seconds"]], [nn["relative_error"]], "*", color="C5", ms=13,
            label=f"NNLS solution ({nn['n_lights']} lights)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time: inverse solve + reduction curve (s, 2 shared cores)")
    ax.set_ylabel("relative error (Eq. 1 / ||b_P||), positive configurations")
    ax.set_title("Staircase: time against error\n(filled: best positive with <= 3 lights; hollow: best "
                 "positive on the whole curve)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(IMG / "bench_staircase_time_error.png", dpi=110)
    plt.close(fig)
    print("wrote docs/img/bench_staircase_curves.png, docs/img/bench_staircase_time_error.png")


if __name__ == "__main__":
    main()
