"""The map benchmark's numbers and page section (``analysis/benchmarks/maps.py`` is its command): the
medians over seeds of every model, the issue's goals per map (#72: a rollout step at least 4x cheaper
than HNN + RK4's at the same width, at a test-horizon error within 2x), and docs/maps.md's section."""
from __future__ import annotations

import statistics

from hnn_analysis.benchmarks import map_protocols as mp
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import machine

COST_GOAL, ERROR_GOAL = 4.0, 2.0        # the issue's: a step 4x cheaper than HNN + RK4's, an error within 2x


def summarize(rows: list[dict]) -> dict:
    """Per model: the median, min and max over seeds of each measured number."""
    out = {}
    for label in dict.fromkeys(r["label"] for r in rows):
        mine = [r for r in rows if r["label"] == label]
        out[label] = {"params": mine[0]["params"], "seeds": len(mine)}
        for key in ("horizon_error", "seconds_per_step", "train_loss", "train_seconds", "energy_error"):
            values = [r[key] for r in mine if r.get(key) is not None]
            if values:
                out[label][key] = [statistics.median(values), min(values), max(values)]
    return out


def goals(summary: dict, protocol: mp.Protocol) -> dict:
    """Per model: HNN + RK4's median seconds per step over its (``cost_ratio``; a map's goal >= 4) and its
    median test-horizon error over HNN + RK4's (``error_ratio``; a map's goal <= 2); for a map, whether
    each goal is met."""
    ref = summary[mp.REFERENCE]
    out = {}
    for label, s in summary.items():
        cost = ref["seconds_per_step"][0] / s["seconds_per_step"][0]
        error = s["horizon_error"][0] / ref["horizon_error"][0]
        out[label] = {"cost_ratio": cost, "error_ratio": error}
        if label in protocol.maps:
            out[label].update(cost_met=cost >= COST_GOAL, error_met=error <= ERROR_GOAL)
    return out


def _g(x, digits: int = 3) -> str:
    return "n/a" if x is None else f"{x:.{digits}g}"


def _spread(triple, scale: float = 1.0) -> str:
    return "n/a" if not triple else f"{triple[0] * scale:.3g} ({triple[1] * scale:.3g}-{triple[2] * scale:.3g})"


def section(result: dict) -> str:
    """The protocol's section of docs/maps.md: the models' medians over seeds, the goals, the step floors."""
    meta, p = result["meta"], result["meta"]["protocol"]
    summary, goal, floors = result["summary"], result["goals"], result["floors"]
    n = len(meta["seeds"])
    lines = [generated_by(meta, f"torch {meta['torch']}, {machine(meta)}, one thread; {meta['seconds']:.0f} s") + "."
             + (" **QUICK smoke run: not the protocol's settings.**" if meta["quick"] else ""), "",
             f"Step h = {p['h']:g}; {p['train_pairs']} training pairs; {p['test_starts']} test "
             f"start{'s' if p['test_starts'] > 1 else ''}, {p['test_steps']} steps each. Every model: {p['steps']} Adam "
             f"steps at rate {p['learn_rate']:g}, " + (f"batches of {p['batch']}" if p["batch"] else "full batch")
             + f", width {p['width']} where it has one. Median over {n} seeds (min-max). Horizon error: the median "
             "over starts of the RMS state error over the test steps. Rollout: `hnn.rollout` from the test starts "
             f"in float32, seconds per step, median of {meta['repeats']} repeats.", "",
             "| model | params | horizon error | rollout us / step | HNN + RK4's step / this one's | error / HNN + RK4's "
             "| train loss | train s |" + (" max true energy error |" if p["name"] == "pendulum" else ""),
             "| --- | ---: | --- | --- | ---: | ---: | --- | ---: |" + (" --- |" if p["name"] == "pendulum" else "")]
    for label, s in summary.items():
        g = goal[label]
        if "cost_met" in g:
            marks = (f"{g['cost_ratio']:.2g}x {'(goal met)' if g['cost_met'] else '(under 4x)'} | "
                     f"{g['error_ratio']:.2g}x {'(goal met)' if g['error_met'] else '(over 2x)'}")
        else:
            marks = f"{g['cost_ratio']:.2g}x | {g['error_ratio']:.2g}x"
        lines.append(f"| {label} | {s['params']} | {_spread(s['horizon_error'])} | {_spread(s['seconds_per_step'], 1e6)} "
                     f"| {marks} | {_spread(s['train_loss'])} | {_g(s['train_seconds'][0])} |"
                     + (f" {_spread(s.get('energy_error'))} |" if p["name"] == "pendulum" else ""))
    failed = [f"{r['label']} at seed {r['seed']} ({r['failed_starts']} of {p['test_starts']})" for r in result["rows"]
              if r.get("failed_starts")]
    if failed:
        lines += ["", "Starts whose rollout failed (the midpoint's iteration did not converge; an infinite error in the "
                  "median; the timing runs every start to the end, the failed ones retired): " + "; ".join(failed) + "."]
    met = [label for label, g in goal.items() if g.get("cost_met") and g.get("error_met")]
    lines += ["", "Goal (issue #72): a rollout step at least 4x cheaper than HNN + RK4's at the same width, at a "
              f"horizon error within 2x. Met by: {', '.join(met) if met else 'no map'} (on the medians over {n} seeds)."]
    if floors:
        lines += ["", f"One step alone, {p['test_starts']} state{'s' if p['test_starts'] > 1 else ''} (seed 0's models, "
                  "as a rollout runs it: no graph, its numpy kernel where it has one), against the arithmetic floor of "
                  "its matrix products each timed alone in its fastest layout (analysis/benchmarks/floor.py), "
                  "alternated in blocks in this process: medians.", "",
                  "| model | step us | HNN + RK4's step / this one's | floor us | step / floor | products |",
                  "| --- | ---: | ---: | ---: | ---: | ---: |"]
        ref = floors.get(mp.REFERENCE)
        for label, f in floors.items():
            cheaper = f"{ref['step_us'] / f['step_us']:.2g}x" if ref else "n/a"
            lines.append(f"| {label} | {f['step_us']:.3g} | {cheaper} | {f['floor_us']:.3g} | {f['ratio']:.3g} | "
                         f"{f['products']} |")
        lines += ["", "The rollout column above is the front door, `hnn.rollout`, whose fixed-step driver checks the "
                  "states at every output point (here every step); this table is the step alone."]
    return "\n".join(lines) + "\n"
