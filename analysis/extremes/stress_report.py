"""The stress study's tables, from its results dict (``stress.json``): the grid per scene, the rollouts
and the precision part."""
from __future__ import annotations

import math
import statistics

from hnn_analysis.extremes.stress_grid import HEAVY, KINDS, NO_FIT, PRECISION_SEEDS, SCENES, applies, outcome
from hnn_analysis import pages
from hnn_analysis.provenance import machine

# why a kind is left out of a scene's table
DOES_NOT_APPLY = {"arm": "they model point bodies, and the arm's links are rods with their own inertia"}


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
    lines = [pages.generated_by(meta, f"{machine(meta)}, {jobs}") + ", "
             f"{meta['seconds']:.0f} s wall, {meta['cpu_seconds']:.0f} s of CPU (load average {meta['load']:.1f} at "
             f"its end, the box shared): seed {results['seed']}, {b['steps']} Adam steps at rate {b['learn_rate']}, "
             f"{b['hidden']} hidden units, {b['rows']} training and {b['rows']} test states, through hnn.train at its "
             "defaults (--units auto: the model in hnn.units.Rescaled; --balance auto) unless the cell says "
             "--units off. Field error: mean over components of |f_j - f_true_j| / |f_true_j| on the test states (a "
             f"zero field scores 1; at or above {NO_FIT} a cell never counts as working). A cell: works (within 2x of "
             "the kind's nominal), degrades (its number, its factor), stops (the error it raised); (rescaled): auto "
             "rescaled its data, per coordinate pair where one scale could not serve.", ""]
    for scene in SCENES:
        rows = [r for r in results["rows"] if r["scene"] == scene]
        kinds = list(dict.fromkeys(r["kind"] for r in rows))
        cells = list(dict.fromkeys(r["cell"] for r in rows))
        absent = [kind for kind in KINDS if not applies(kind, scene)]
        note = f" ({', '.join(absent)}: {DOES_NOT_APPLY[scene]})" if absent else ""
        lines += [f"**{scene}**{note}", "", "| cell | " + " | ".join(kinds) + " |", "| --- " * (len(kinds) + 1) + "|"]
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
    if results.get("heavy"):
        lines += [""] + heavy_text(results["heavy"])
    if results.get("precision"):
        lines += [""] + precision_text(results["precision"])
    return "\n".join(lines) + "\n"


def heavy_text(rows: list[dict]) -> list[str]:
    """The heavy mass (dp/dt 500x dq/dt): per kind and --units, each measure's median (min-max) over seeds."""
    seeds = sorted({r["seed"] for r in rows})
    lines = [f"**heavy mass** (m = k = {HEAVY:g}: dp/dt of RMS {HEAVY:g} against dq/dt of 1; median (min-max) over seeds "
             f"{', '.join(map(str, seeds))})", "",
             "| kind (--units) | field error | M^-1 error | rollout error (3 periods) |", "| --- | --- | --- | --- |"]
    for kind in dict.fromkeys(r["kind"] for r in rows):
        for units in dict.fromkeys(r["units"] for r in rows):
            mine = [r for r in rows if r["kind"] == kind and r["units"] == units]
            cells = []
            for key in ("field_error", "inverse_mass_error", "rollout_error"):
                values = sorted(r[key] for r in mine if key in r)
                stopped = sum(1 for r in mine if key == "rollout_error" and "rollout_stop" in r)
                text = (f"{statistics.median(values):.3g} ({values[0]:.3g}-{values[-1]:.3g})" if len(values) > 1
                        else f"{values[0]:.3g}" if values else "-")
                cells.append(text + (f"; {stopped} of {len(mine)} diverged" if stopped else ""))
            lines.append(f"| {kind} ({units}) | " + " | ".join(cells) + " |")
    return lines


def scan_text(rows: list[dict], meta: dict, budget: dict) -> str:
    """The scan: per kind and cell, the field error's median (min-max) over seeds and its factor over the
    unit cell's median; cells that --units auto would rescale marked."""
    jobs = f"{meta['jobs']} processes of one torch thread" if meta.get("jobs", 1) > 1 else "one torch thread"
    seeds = sorted({r["seed"] for r in rows})
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    lines = [pages.generated_by(meta, f"{machine(meta)}, {jobs}") + f", {meta['seconds']:.0f} s "
             f"wall: the spring (m = k = 1) with its states read a times theirs (q, p and their rates alike) or its "
             f"rates alone b times theirs (a faster clock), fit in the data's own units (--units off) by hnn.train, "
             f"{budget['steps']} Adam steps at rate {budget['learn_rate']}, {budget['hidden']} hidden units, "
             f"{budget['rows']} states; field error, median (min-max) over seeds {', '.join(map(str, seeds))}, and "
             "its factor over the unit cell's median. *: --units auto rescales these data.", "",
             "| cell | " + " | ".join(kinds) + " |", "| --- " * (len(kinds) + 1) + "|"]
    for a, b in dict.fromkeys((r["a"], r["b"]) for r in rows):
        label = f"states x{a:g}" if b == 1 else f"rates x{b:g}"
        cells = []
        for kind in kinds:
            mine = sorted(r["error"] for r in rows if r["kind"] == kind and (r["a"], r["b"]) == (a, b))
            unit = statistics.median(r["error"] for r in rows if r["kind"] == kind and (r["a"], r["b"]) == (1, 1))
            mark = "*" if any(r["auto_rescales"] for r in rows if (r["a"], r["b"]) == (a, b)) else ""
            cells.append(f"{statistics.median(mine):.3g} ({mine[0]:.3g}-{mine[-1]:.3g}), "
                         f"{statistics.median(mine) / unit:.2g}x{mark}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def grid_seeds(results: dict) -> pages.Seeds:
    """The grid's cells are one fit each; its precision rows measure the seeds' spread."""
    return pages.Seeds(1, f"each cell is one fit (seed {results['seed']}) of a grid of {len(results['rows'])}; the "
                          "precision rows measure the spread over seeds 0, 1, 2 that a cell's factor of 2 must exceed")


def scan_seeds(results: dict) -> pages.Seeds:
    return pages.Seeds(len({row["seed"] for row in results["scan"]}))


def scan_results_text(results: dict) -> str:
    return scan_text(results["scan"], results["meta"], results["budget"])


def grid_text(results: dict) -> str:
    return text(results, results["meta"])
