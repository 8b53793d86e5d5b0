"""The work-precision study's report (``analysis/integrator_study/work_precision.py`` is its command):
each solver's seconds at equal error, the tables and the plots.

    front = pareto_front([(error, seconds), ...])   # the settings no other beats on both
    at_error(front, 1e-6)                           # seconds at error 1e-6, log-log between neighbours

Equal error, not equal tolerance: a solver's seconds at an error level come from its own curve, by
linear interpolation of log(seconds) in log(error) between the two settings of its Pareto front around
that level (never extrapolated: a level outside a curve's errors is left out), so two solvers whose
tolerances mean different errors are compared where they are equally accurate.
"""
from __future__ import annotations

import math
import statistics
from pathlib import Path

import matplotlib.ticker

from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import machine

LEVELS = tuple(10.0 ** (-k / 2) for k in range(4, 21))      # error levels: 1e-2 .. 1e-10, half decades
GOAL = 2.0                                                   # the goal: ours at least 2x faster
# ours: one step size per row under the PI rule (the default), and steps='shared' (one for the batch under
# scipy's step rule, solve_ivp's terms; on one state, scipy's rule on that row)
OURS = ("hnn dopri5", "hnn dop853", "hnn dopri5 shared", "hnn dop853 shared")
BEST = "best of ours"


def pareto_front(points) -> list[tuple[float, ...]]:
    """The points ``(error, seconds, ...)`` that no other point beats on both error and seconds (error > 0),
    by error ascending (so seconds descending)."""
    front = []
    for point in sorted(p for p in points if p[0] > 0 and p[1] > 0):
        if not front or point[1] < front[-1][1]:
            front.append(point)
    return front


def at_error(front, error: float, index: int = 1) -> float | None:
    """Component ``index`` (1: the seconds) of ``front`` (``pareto_front``'s) at ``error``: interpolated
    log-log between the two points around it, None outside the front's errors."""
    if not front or not front[0][0] <= error <= front[-1][0]:
        return None
    for lo, hi in zip(front, front[1:]):
        if lo[0] <= error <= hi[0]:
            if hi[0] == lo[0]:
                return lo[index]
            w = math.log(error / lo[0]) / math.log(hi[0] / lo[0])
            return math.exp((1 - w) * math.log(lo[index]) + w * math.log(hi[index]))
    return front[0][index]          # a front of one point, at its own error


def curves(rows: list[dict], round_index: int | None = None) -> dict:
    """``{(task, model, batch, solver): front of (error, seconds, field seconds, calls, rows evaluated)}``: the
    median seconds over the rounds, or (``round_index``) that round's."""
    points: dict = {}
    for r in rows:
        if r["status"] == "ok":
            key = (r["task"], r["model"], r["batch"], r["solver"])
            seconds = r["seconds"] if round_index is None else r["round_seconds"][round_index]
            points.setdefault(key, []).append((r["error"], seconds, r["field_s"], r["calls"], r["rows"]))
    return {key: pareto_front(p) for key, p in points.items()}


def rounds(rows: list[dict]) -> int:
    """The rounds every measured setting has its seconds of (0 for results saved with medians alone)."""
    return min((len(r.get("round_seconds", ())) for r in rows if r["status"] == "ok"), default=0)


def comparisons(rows: list[dict]) -> list[dict]:
    """At every level of ``LEVELS`` both curves reach: ours and each peer's seconds (the medians' curves), their
    ratio (peer / ours), the calls and rows evaluated of each, and the bound (peer seconds / the seconds ours spent
    inside the field): the most a solver with no work of its own, making our calls, could gain. With the rounds'
    seconds, ``round_ratios`` holds each round's ratio on that round's curves (the solvers of a round ran one
    after another at each tolerance) and ``ratio`` is their median: a drift of the box's load between rounds
    then moves both sides of a ratio alike."""
    fronts = curves(rows)
    per_round = [curves(rows, k) for k in range(rounds(rows))]
    out = []
    for (task, model, batch, ours), mine in fronts.items():
        if ours not in OURS:
            continue
        for (task2, model2, batch2, peer), theirs in fronts.items():
            if (task2, model2, batch2) != (task, model, batch) or peer in OURS:
                continue
            for level in LEVELS:
                a, b = at_error(mine, level), at_error(theirs, level)
                if a is None or b is None:
                    continue
                paired = [_ratio(f, (task, model, batch), ours, peer, level) for f in per_round]
                paired = [r for r in paired if r is not None]
                out.append({"task": task, "model": model, "batch": batch, "ours": ours, "peer": peer, "level": level,
                            "ours_s": a, "peer_s": b, "ratio": statistics.median(paired) if paired else b / a,
                            "round_ratios": paired, "bound": b / at_error(mine, level, 2),
                            "ours_calls": at_error(mine, level, 3), "peer_calls": at_error(theirs, level, 3),
                            "ours_rows": at_error(mine, level, 4), "peer_rows": at_error(theirs, level, 4)})
    return out


def _ratio(fronts: dict, field: tuple, ours: str, peer: str, level: float) -> float | None:
    """Peer / ours seconds at ``level`` on one round's ``fronts``; None where either curve does not reach it."""
    a, b = at_error(fronts.get((*field, ours), []), level), at_error(fronts.get((*field, peer), []), level)
    return None if a is None or b is None else b / a


def _peers(rows) -> list[str]:
    return list(dict.fromkeys(r["solver"] for r in rows if r["solver"] not in OURS))


def _span(values) -> str:
    if not values:
        return "-"
    lo, hi = min(values), max(values)
    return f"{lo:.2f}x" if f"{lo:.2f}" == f"{hi:.2f}" else f"{lo:.2f}-{hi:.2f}x"


def summary_table(results: dict) -> list[str]:
    """Per field, batch and method of ours: each peer's seconds / ours over the error levels both reach
    (min-max), and how many levels reach ``GOAL``."""
    comps = comparisons(results["rows"])
    peers = _peers(results["rows"])
    lines = ["| task | model | states | ours | " + " | ".join(f"{p} / ours" for p in peers) + " |",
             "| --- | --- | ---: | --- |" + " ---: |" * len(peers)]
    keys = dict.fromkeys((c["task"], c["model"], c["batch"], c["ours"]) for c in comps)
    for task, model, batch, ours in keys:
        cells = []
        for peer in peers:
            mine = [c for c in comps if (c["task"], c["model"], c["batch"], c["ours"], c["peer"]) ==
                    (task, model, batch, ours, peer)]
            reached = sum(c["ratio"] >= GOAL for c in mine)
            cells.append(f"{_span([c['ratio'] for c in mine])} ({reached}/{len(mine)})" if mine else "-")
        lines.append(f"| {task} | {model} | {batch} | {_ours(ours)} | " + " | ".join(cells) + " |")
        if ours == [o for (t, m, b, o) in keys if (t, m, b) == (task, model, batch)][-1]:
            lines.append(_best_row(comps, peers, task, model, batch))
    return lines


def _best_row(comps: list[dict], peers: list[str], task: str, model: str, batch: int) -> str:
    """At each level, the fastest of ours there against each peer (``BEST``): the user's pick of ours, with how
    many levels it is level or faster at (the rounds' median ratio >= 1) and, of the others, how many the rounds
    cannot separate from level (some round >= 1): only the rest are slower in every round."""
    cells = []
    for peer in peers:
        by_level: dict = {}
        for c in comps:
            if (c["task"], c["model"], c["batch"], c["peer"]) == (task, model, batch, peer):
                by_level.setdefault(c["level"], []).append(c)
        best = {level: _best(found) for level, found in by_level.items()}
        level_up = sum(median >= 1.0 for median, _ in best.values())
        split = sum(median < 1.0 <= top for median, top in best.values())
        words = f"{level_up}/{len(best)} level or faster" + (f"; {split} the rounds cannot separate" if split else "")
        cells.append(f"{_span([median for median, _ in best.values()])} ({words})" if best else "-")
    return f"| {task} | {model} | {batch} | **{BEST}** | " + " | ".join(cells) + " |"


def _best(found: list[dict]) -> tuple[float, float]:
    """The fastest of ours at one level against one peer: in each round the largest ratio of ours that round,
    then ``(their median, their largest)`` (a user who times each of ours picks the fastest); without rounds,
    the largest ratio, twice."""
    counts = {len(c["round_ratios"]) for c in found}
    if len(counts) != 1 or not counts.pop():
        top = max(c["ratio"] for c in found)
        return top, top
    per_round = [max(per) for per in zip(*(c["round_ratios"] for c in found))]
    return statistics.median(per_round), max(per_round)


def _ours(solver: str) -> str:
    return solver.removeprefix("hnn ")


def level_table(results: dict, task: str, model: str) -> list[str]:
    """Every error level of one field: the seconds of ours and of each peer there, the ratio and the bound."""
    comps = [c for c in comparisons(results["rows"]) if (c["task"], c["model"]) == (task, model)]
    lines = ["| states | error | ours | ours (s) | peer | peer (s) | peer / ours (the rounds' median) | calls: peer / ours | "
             "rows: peer / ours | bound: peer / our field time |",
             "| ---: | ---: | --- | ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    for c in comps:
        lines.append(f"| {c['batch']} | {c['level']:.0e} | {_ours(c['ours'])} | {c['ours_s']:.4f} | {c['peer']} | "
                     f"{c['peer_s']:.4f} | {c['ratio']:.2f}x | {c['peer_calls'] / c['ours_calls']:.2f} | "
                     f"{c['peer_rows'] / c['ours_rows']:.2f} | {c['bound']:.2f}x |")
    return lines


def seconds_table(results: dict, task: str, model: str) -> list[str]:
    """One field at every error level one of ours reaches: each solver's seconds there (interpolated on its
    own curve; blank where its curve does not reach) and the seconds ours spent inside the field."""
    fronts = {key[2:]: front for key, front in curves(results["rows"]).items() if key[:2] == (task, model)}
    solvers = list(dict.fromkeys(r["solver"] for r in results["rows"]))
    lines = ["| states | error | " + " | ".join(f"{s} (s)" for s in solvers) + " | " +
             " | ".join(f"{_ours(s)} in the field (s)" for s in OURS) + " |",
             "| ---: | ---: |" + " ---: |" * (len(solvers) + len(OURS))]
    for batch in sorted({key[0] for key in fronts}, reverse=True):
        for level in LEVELS:
            mine = [at_error(fronts.get((batch, s), []), level) for s in OURS]
            if all(m is None for m in mine):
                continue
            cells = [at_error(fronts.get((batch, s), []), level) for s in solvers]
            field = [at_error(fronts.get((batch, s), []), level, 2) for s in OURS]
            lines.append(f"| {batch} | {level:.0e} | " + " | ".join("" if c is None else f"{c:.4f}" for c in cells + field)
                         + " |")
    return lines


def profile_table(results: dict, task: str, model: str, rtols=(1e-7, 1e-9)) -> list[str]:
    """Where each solver's seconds go on one field at ``rtols``: inside the field's calls, and its own."""
    lines = ["| states | rtol | solver | seconds | error | calls | rows a call | in the field (s) | own (s) | "
             "own a call (us) | one call alone (us) |",
             "| ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in results["rows"]:
        if (r["task"], r["model"]) != (task, model) or r["status"] != "ok" or \
                not any(math.isclose(r["rtol"], x) for x in rtols):
            continue
        own = r["seconds"] - r["field_s"]
        lines.append(f"| {r['batch']} | {r['rtol']:.0e} | {r['solver']} | {r['seconds']:.4f} | {r['error']:.2e} | "
                     f"{r['calls']} | {r['rows'] / r['calls']:.1f} | {r['field_s']:.4f} | {own:.4f} | "
                     f"{own / r['calls'] * 1e6:.1f} | {r['call_us']:.1f} |")
    return lines


def why_table(why: dict) -> str:
    lines = [f"**Why equal tolerances are not equal errors** (the learned spring HNN, {why['starts']} starts uniform in "
             f"[-1, 1]^2, t in [0, {why['span']:g}], {why['outputs']} output times, float64; error: max over "
             "starts and times against DOP853 at rtol 1e-13; calls: batched calls of the field; rows: the states "
             "they evaluated)", "",
             "| rtol = atol | variant | calls | rows | max error |", "| ---: | --- | ---: | ---: | ---: |"]
    for r in why["rows"]:
        lines.append(f"| {r['rtol']:.0e} | {r['variant']} | {r['calls']} | {r['rows']} | {r['error']:.2e} |")
    return "\n".join(lines) + "\n"


def header(results: dict) -> str:
    meta = results["meta"]
    versions = ", ".join(f"{k} {v}" for k, v in meta["peers"].items() if v)
    return (generated_by(meta, f"{machine(meta)}, torch {meta['torch']}, numpy {meta['numpy']}, {versions}; float64, one "
                               f"torch thread; {meta['repeats']} round(s), the median kept; {meta['seconds']:.0f} s; "
                               f"other processes kept {meta['others_load']:.1f} cores busy on average")
            + ". Error: max |x - x_ref| over the states and the study's output times, "
            "against scipy's DOP853 at rtol = atol = 1e-13 on the same field. Seconds at an error level: "
            "interpolated log-log along each solver's Pareto front (tolerances rtol = atol, 1e-3 .. 1e-11 in "
            "half decades), never extrapolated; ratios above 1 mean ours is faster.")


def markdown(results: dict, detail: bool = True) -> str:
    """The whole report (``detail``: every field's tables, else the learned spring HNN's seconds alone)."""
    paired = ("each ratio the median over the rounds of that round's ratio, the solvers of a round timed one after "
              "another at each tolerance; " if rounds(results["rows"]) else "")
    lines = [header(results), "", f"**Seconds at equal error, peer / ours** ({paired}min-max over the error levels both "
             f"reach; in brackets, the levels where ours is at least {GOAL:g}x faster; {BEST}: at each level the fastest of "
             "ours there, in brackets the levels where it is at least as fast as the peer and, of the rest, those where "
             "the rounds cannot separate it from level: some rounds faster, some slower)", "", *summary_table(results)]
    fields = list(dict.fromkeys((r["task"], r["model"]) for r in results["rows"]))
    for task, model in (fields if detail else [f for f in fields if f == ("spring", "hnn")]):
        lines += ["", f"**{task} {model}: seconds at each error level** (each solver on its own curve; the last "
                      "columns: the seconds ours spent inside the field's calls, under which no solver making our "
                      "calls can go)", "", *seconds_table(results, task, model)]
    for task, model in (fields if detail else []):
        lines += ["", f"**{task} {model}, every error level and pair** (the bound: the peer's seconds over the "
                      "seconds ours spent inside the field, the most a solver of no cost of its own could reach "
                      "with our calls)", "", *level_table(results, task, model)]
    for task, model in [f for f in fields if f == ("spring", "hnn")]:
        lines += ["", f"**{task} {model}: where the seconds go** (in the field: inside the field's calls; own: "
                      "the rest, the solver's own work; one call alone: the field on the same states, timed in a "
                      "loop in the same process)", "", *profile_table(results, task, model)]
    for note in results["notes"]:
        lines += ["", f"Note: {note}"]
    return "\n".join(lines) + "\n"


def _panel(ax, rows: list[dict], title: str) -> None:
    """Error against seconds on ``ax``: every solver's settings faint, its Pareto front bold; ours solid."""
    for solver in dict.fromkeys(r["solver"] for r in rows):
        mine = [r for r in rows if r["solver"] == solver and r["status"] == "ok" and r["error"] > 0]
        if not mine:
            continue
        style = "o-" if solver in OURS else "s--"
        line, = ax.loglog(*zip(*sorted((r["seconds"], r["error"]) for r in mine)), style, ms=3, lw=1, alpha=0.3)
        front = pareto_front([(r["error"], r["seconds"]) for r in mine])
        ax.loglog([p[1] for p in front], [p[0] for p in front], style, ms=4, lw=1.5, color=line.get_color(),
                  label=solver)
    ax.set(title=title, xlabel="seconds (float64, 1 thread)", ylabel="max error")
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.grid(True, which="both", alpha=0.3)


def plot(task: str, rows: list[dict], path: Path) -> Path:
    """One task: a panel per model and batch (columns and rows)."""
    models = list(dict.fromkeys(r["model"] for r in rows))
    batches = sorted({r["batch"] for r in rows}, reverse=True)
    return _grid([[(f"{task} {model}: {_states(batch)}", [r for r in rows if (r["model"], r["batch"]) == (model, batch)])
                   for model in models] for batch in batches], path,
                 f"{task}: work-precision of the adaptive solvers on learned fields (faint: every tolerance; "
                 "bold: the Pareto front)")


def overview(rows: list[dict], path: Path, model: str = "hnn") -> Path:
    """``model`` on every task: a panel per task and batch (columns and rows), the page's figure."""
    tasks = list(dict.fromkeys(r["task"] for r in rows if r["model"] == model))
    batches = sorted({r["batch"] for r in rows}, reverse=True)
    return _grid([[(f"{task} {model}: {_states(batch)}", [r for r in rows if (r["task"], r["model"], r["batch"]) ==
                                                            (task, model, batch)]) for task in tasks] for batch in batches],
                 path, f"Work-precision on the learned {model} fields (faint: every tolerance; bold: the Pareto "
                       "front; ours solid, the peers dashed)")


def _states(batch: int) -> str:
    return f"{batch} state{'s' if batch > 1 else ''}"


def _grid(panels: list[list[tuple[str, list[dict]]]], path: Path, title: str) -> Path:
    from hnn_analysis.plotting import plt, save_figure
    fig, axes = plt.subplots(len(panels), len(panels[0]), figsize=(3.9 * len(panels[0]), 3.1 * len(panels)),
                             squeeze=False)
    for row, axes_row in zip(panels, axes):
        for (name, rows), ax in zip(row, axes_row):
            _panel(ax, rows, name)
    legend = {}                                  # one legend for the figure: every solver any panel drew
    for ax in axes.flat:
        legend.update(zip(*reversed(ax.get_legend_handles_labels())))
    fig.legend(legend.values(), legend.keys(), loc="lower center", ncol=len(legend), fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return save_figure(fig, path)
