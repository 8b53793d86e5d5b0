"""The stress study's tables, from its results dict (``stress.json``): the grid per scene, the rollouts
and the precision part."""
from __future__ import annotations

import math

from hnn_analysis.extremes.stress_grid import NO_FIT, PRECISION_SEEDS, SCENES, outcome
from hnn_analysis.provenance import machine


def precision_text(rows: list[dict]) -> list[str]:
    """Per dtype: each seed's error at 1 and 2 threads, their largest relative gap, the spread over seeds."""
    lines = ["**precision** (the HNN on the spring, the nominal budget: field error at seeds "
             f"{', '.join(map(str, PRECISION_SEEDS))})", "",
             "| dtype | 1 thread | 2 threads | largest gap 1 vs 2 threads, same seed | spread over seeds (max / min) |",
             "| --- | --- | --- | --- | --- |"]
    for dtype in ("float32", "float64"):
        one, two = ([r.get("error", math.nan) for r in rows if r["dtype"] == dtype and r["threads"] == t] for t in (1, 2))
        gap = max(abs(a - b) / a for a, b in zip(one, two))
        lines.append(f"| {dtype} | {', '.join(f'{e:.4g}' for e in one)} | {', '.join(f'{e:.4g}' for e in two)} | "
                     f"{gap:.2g} | {max(one) / min(one):.2g} |")
    return lines + [""]


def text(results: dict, meta: dict) -> str:
    b = results["budget"]
    jobs = f"{meta['jobs']} processes of one torch thread" if meta.get("jobs", 1) > 1 else "one torch thread"
    lines = [f"From `{meta['command']}` at commit {meta['commit']} ({machine(meta)}, {jobs}), "
             f"{meta['seconds']:.0f} s wall, {meta['cpu_seconds']:.0f} s of CPU (load average {meta['load']:.1f} at "
             f"its end, the box shared): seed {results['seed']}, {b['steps']} Adam steps at rate {b['learn_rate']}, "
             f"{b['hidden']} hidden units, {b['rows']} training and {b['rows']} test states, the default --balance auto. "
             "Field error: mean over components of |f_j - f_true_j| / |f_true_j| on the test states (a zero field "
             f"scores 1; at or above {NO_FIT} a cell never counts as working). A cell: works (within 2x of the "
             "kind's nominal), degrades (its number, its factor), stops (the error it raised).", ""]
    for scene in SCENES:
        rows = [r for r in results["rows"] if r["scene"] == scene]
        kinds = list(dict.fromkeys(r["kind"] for r in rows))
        cells = list(dict.fromkeys(r["cell"] for r in rows))
        lines += [f"**{scene}**", "", "| cell | " + " | ".join(kinds) + " |", "| --- " * (len(kinds) + 1) + "|"]
        for cell in cells:
            out = []
            for kind in kinds:
                row = next(r for r in rows if r["kind"] == kind and r["cell"] == cell)
                nominal = next(r for r in rows if r["kind"] == kind and r["cell"] == "nominal")
                out.append(outcome(row, None if cell == "nominal" else nominal))
            lines.append(f"| {cell} | " + " | ".join(out) + " |")
        lines.append("")
    kinds = list(dict.fromkeys(r["kind"] for r in results["rollouts"]))
    cells = list(dict.fromkeys(r["cell"] for r in results["rollouts"]))
    lines += ["**spring, the nominal models' RK4 rollouts** (largest relative change of the true energy, 4 starts)", "",
              "| cell | " + " | ".join(kinds) + " |", "| --- " * (len(kinds) + 1) + "|"]
    for cell in cells:
        out = [outcome(r, r.get("nominal")) for kind in kinds for r in results["rollouts"]
               if r["kind"] == kind and r["cell"] == cell]
        lines.append(f"| {cell} | " + " | ".join(out) + " |")
    if results.get("precision"):
        lines += [""] + precision_text(results["precision"])
    return "\n".join(lines) + "\n"
