"""Stability rows for the best k-light search (engine.best_lights), as markdown.

    .venv/bin/python benchmarks/stability_best_lights.py [--k-max 6]

The cases of benchmarks/stability_table.py, plus degenerate transfer matrices (every light
duplicated by a half-area twin and 5 dark lights, on the infeasible-contrast room; all-zero
targets on the reference room). Per case: best_k_curve (error- and correlation-scored, with
swap), lower_bounds and the tolerance LP (+-5 %, +-20 %), with the user messages (curve_notes,
the LP's message). A case that fails at set-up shows the InverseError the user sees. Prints
the table (for docs/stability.md); checked by tests/test_stability_best_lights.py.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "benchmarks"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))
import stability_table as st  # noqa: E402
from relight_addon.engine import best_lights as bl  # noqa: E402
from relight_addon.engine.scene import SceneError  # noqa: E402


def rows_for(name, T, b, area, norm, k_max):
    out = []
    t = time.perf_counter()
    lb = bl.lower_bounds(T, b, k_max)
    t_lb = time.perf_counter() - t
    lp = [bl.least_power_within_tolerance(T, b, area, x) for x in (0.05, 0.2)]
    for score in bl.SCORES:
        t = time.perf_counter()
        curve = bl.best_k_curve(T, b, k_max, area, score=score)
        dt = time.perf_counter() - t
        finite = all(np.isfinite(p.error) and np.all(np.isfinite(p.exitance)) for p in curve)
        neg = sum(int((p.exitance < 0).any()) for p in curve)
        mono = all(q.error <= p.error * (1 + 1e-12) + 1e-300 for p, q in zip(curve, curve[1:]))
        below = all(lb.at(p.k) <= p.error for p in curve)
        k3 = min(3, len(curve))
        out.append({
            "case": name, "score": score, "seconds": dt, "lb_seconds": t_lb, "finite": finite, "negative": neg,
            "monotone": mono, "bound_below": below,
            "rel": {k: curve[k - 1].relative_error for k in (1, 3, k_max) if k <= len(curve)},
            "lights3": curve[k3 - 1].n_lights, "bound3": lb.at(k3) / (norm if norm > 0 else 1.0),
            "exact3": bool(lb.exact[k3 - 1]), "nnls": lb.nnls_relative,
            "notes": bl.curve_notes(curve, lb, norm, k=k3),
            "lp": [(r.status, r.message) for r in lp]})
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--k-max", type=int, default=6)
    args = ap.parse_args()
    K = args.k_max
    rows = []
    cases = st.case_builders()
    for name, (desc, build) in cases.items():
        prob, err = st.build_case(build)
        if prob is not None:
            try:
                T = prob.transfer
            except (SceneError, ValueError) as exc:
                prob, err = None, f"{type(exc).__name__}: {exc}"
        if prob is None:
            rows.append({"case": name, "setup": err})
            print(f"{name}: set-up fails: {err}", flush=True)
            continue
        rows += rows_for(name, T, prob.b_target, prob.light_area, prob.target_norm, K)
        print(f"{name}: done", flush=True)
        if name == "infeasible contrast":
            n = T[0].shape[1]
            T2 = [np.hstack([t, t, np.zeros((t.shape[0], 5))]) for t in T]
            A2 = np.concatenate([prob.light_area, prob.light_area / 2, np.ones(5)])
            rows += rows_for("duplicate + dark lights (on infeasible contrast)", T2, prob.b_target, A2,
                             prob.target_norm, K)
            del n
        if name == "room":
            rows += rows_for("all-zero targets (room)", T, np.zeros_like(prob.b_target), prob.light_area, 0.0, K)

    print()
    print(f"| case | score | time (s) | finite, no negative, monotone, bound <= error | rel. error k = 1 / 3 / {K} "
          "| lights at k = 3 | bound at 3 (exact?) / NNLS floor | notes (k = 3) | LP \u00b15 % | LP \u00b120 % |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "setup" in r:
            print(f"| {r['case']} | any | - | - | - | - | - | set-up fails: {r['setup'].replace('|', '/')} | - | - |")
            continue
        ok = "yes" if (r["finite"] and r["negative"] == 0 and r["monotone"] and r["bound_below"]) else "**no**"
        rel = " / ".join(f"{r['rel'][k]:.3g}" for k in sorted(r["rel"]))
        notes = "; ".join(r["notes"]).replace("|", "/")
        lp = [f"{s}: {m}".replace("|", "/") for s, m in r["lp"]]
        print(f"| {r['case']} | {r['score']} | {r['seconds']:.3f} | {ok} | {rel} | {r['lights3']} | "
              f"{r['bound3']:.3g} ({'exact' if r['exact3'] else 'bound'}) / {r['nnls']:.3g} | {notes} | "
              f"{lp[0]} | {lp[1]} |")


if __name__ == "__main__":
    main()
