"""The peers' table as markdown (docs/peers.md's generated section): every protocol row's kinds beside
the published numbers, and the card of which kind to use on a chain.
"""
from __future__ import annotations

import hnn
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import machine

def _cell(entry: dict | None) -> str:
    if entry is None:
        return "not trained"
    failed = entry.get("failed") or {}
    if "mean" not in entry and len(failed) > 1:     # every seed failed: each seed's how, to its first clause
        return f"failed on all {len(failed)} seeds: " + "; ".join(
            f"seed {seed} {': '.join(why.split(': ')[:2])}" for seed, why in failed.items())
    if "blew_up" in entry:
        return f"blew up: {entry['blew_up']}"
    if "diverged" in entry:
        return f"failed in training: {entry['diverged']}"
    if len(entry.get("seeds", ())) > 1 or failed:   # the mean over seeds, their range, how many, how many failed
        seeds = entry["seeds"]
        spread = f"{entry['low']:.1e}..{entry['high']:.1e}, {len(seeds)} seeds" if len(seeds) > 1 else "1 seed"
        return f"{entry['mean']:.2e} ({spread}" + (f"; {len(failed)} more failed)" if failed else ")")
    return f"{entry['mean']:.2e} ({entry['median']:.2e})"


def _seeds_sentence(seeds) -> str:
    if len(seeds) == 1:
        return f"One seed ({seeds[0]}) a kind: each cell is that run's mean (median) over the test starts."
    return (f"{len(seeds)} seeds ({seeds[0]}..{seeds[-1]}) a kind: each cell is the mean over the seeds of each "
            "seed's mean over the test starts, with the seeds' range.")


def markdown(results: dict) -> str:
    """The generated section of docs/peers.md: the peers' numbers beside ours, same metric."""
    published = hnn.load_task("chain", "protocols").CHNN_PUBLISHED
    meta = results["meta"]
    names = meta["kinds"]
    seeds = meta.get("seeds", [0])
    several = len(seeds) > 1
    lines = []
    if meta["quick"]:
        lines += ["**QUICK smoke run** (`--quick`: small data, few steps, few test starts): these numbers test the "
                  "pipeline and say nothing about the kinds; the full table comes from `python analysis/peers.py "
                  "--jobs 2 --update-docs`." + (" Cut: " + "; ".join(meta["quick_cuts"]) + "."
                                                if meta.get("quick_cuts") else ""), ""]
    walls = [wall for row in results["rows"].values() for s in row["seconds"].values()
             for wall in s.get("walls", [s.get("wall")]) if wall]
    reused = meta.get("reused", 0)
    if not meta["seconds"]["training"]:
        trained = f"every run reused (their recorded training wall times sum to {sum(walls):.0f} s)"
    elif reused:        # a rerun after an interruption: say what this sitting trained, and what the table holds
        trained = (f"training {meta['seconds']['training']:.0f} s for {meta['trained']} runs, {reused} reused from an "
                   f"earlier sitting (every run's recorded training wall time: {sum(walls):.0f} s in all)")
    else:
        trained = f"training {meta['seconds']['training']:.0f} s"
    lines += [generated_by(meta, machine(meta)) + "; "
              f"{trained}, measuring {meta['seconds']['measuring']:.0f} s (every run's rollouts, in the sitting that "
              f"recorded it), timing the kinds {meta['seconds'].get('timing', 0):.0f} s. Training seconds in the tables: each "
              "run's steps at the rate of short bursts of the same config alone on one thread (what it costs on a "
              "quiet core; with several seeds, the median of the seeds' runs' timings; its recorded wall time is in "
              "peers.json; a run whose bursts, a fresh model's first steps, fail in training is left untimed). "
              f"Each CHNN-protocol kind trains {meta['steps']} steps of batch 200, {meta['steps'] / 4:g} of CHNN's "
              "epochs of 800 snippets (theirs: 2000), by "
              f"{meta.get('optimizer', 'adam')} with a {meta.get('schedule', 'constant')} learning rate (theirs: AdamW, "
              "cosine). " + _seeds_sentence(seeds) +
              f" Training curves (seed {seeds[0]}'s runs): "
              "[figures/peers-curves.png](figures/peers-curves.png).", "",
              "### CHNN protocol (Finzi et al. 2020): geometric-mean relative error of the Cartesian rollout, "
              + ("mean over the seeds (their range)" if several else
                 "mean (median) over the test starts") + "; the floor: mean (median) over the test starts", "",
              "| N | published HNN (mechanical) | published CHNN | published CLNN | published NeuralODE | published floor | "
              + " | ".join(f"ours: {kind}" for kind in names) + " | our floor | our training s (one thread) |",
              "| --- " * (7 + len(names)) + "| --- |"]
    for name, row in results["rows"].items():
        if not name.startswith("chain"):
            continue
        n = int(name[len("chain"):])
        peer = published.get(n, {})
        seconds = ", ".join(f"{kind} {s['seconds']:.0f}" for kind, s in row["seconds"].items())
        lines.append(f"| {n} | " + " | ".join(
            f"{peer[k][0]:.2e} ({peer[k][1]:.2e})" if k in peer else "" for k in ("HNN", "CHNN", "CLNN", "NeuralODE", "floor"))
            + " | " + " | ".join(_cell(row.get(kind)) for kind in names)
            + f" | {_cell(row['floor'])} | {seconds} |")
    lines += card(results)
    lines += against_published(results, published)
    lnn = results["rows"].get("lnn")
    if lnn is not None:
        lnn_published = hnn.load_task("chain", "protocols").LNN_PUBLISHED
        horizon = meta.get("lnn_horizon") or hnn.load_task("chain", "protocols").LNN["t_end"]
        lines += ["", f"### LNN double pendulum (Cranmer et al. 2020): |E(z^_T) - E(z_T)| / 29.4 at T = {horizon:g} s, "
                  + ("mean over the seeds (their range) of the mean" if several else
                     "mean (median)") + " over the starts (ours: dopri5 at rtol 1e-8)", "",
                  "| kind | energy error | training steps | training s (one thread) |", "| --- | --- | ---: | ---: |"]
        lines += [f"| published {k} | {v:.2g} | | |" for k, v in lnn_published.items()]
        lines += [f"| ours: {kind} | {_cell(lnn.get(kind))} | "
                  + (f"{lnn['seconds'][kind]['steps'] - 1} | {lnn['seconds'][kind]['seconds']:.0f} |"
                     if kind in lnn["seconds"] else " | |") for kind in names]
    return "\n".join(lines) + "\n"


def inseparable(row: dict, best: str, kinds) -> list[str]:
    """The kinds of ``kinds`` whose seeds' range of mean errors overlaps ``best``'s (``over_seeds``): the
    seeds cannot tell them from the best. Empty with one seed, where nothing is separated by seeds."""
    if len(row[best].get("seeds", ())) < 2:
        return []
    return [kind for kind in kinds if kind != best and len(row[kind].get("seeds", ())) > 1
            and row[kind]["low"] <= row[best]["high"]]


def as_cheap(costs: dict, enough: str, kinds) -> list[str]:
    """The kinds of ``kinds`` whose range of training-cost timings (``cost_over_seeds``: one per seed's run)
    overlaps ``enough``'s: the timings cannot say which trains faster. Empty where a kind has one timing."""
    mine = costs.get(enough, {})
    if "high" not in mine or mine["low"] == mine["high"]:
        return []
    return [kind for kind in kinds if kind != enough and "low" in costs.get(kind, {})
            and costs[kind]["low"] <= mine["high"] and mine["low"] <= costs[kind]["high"]]


def card(results: dict) -> list[str]:
    """The chain card's lines: at each N the best kind on the mean (over seeds where there are several), the
    kind that is enough, the one of least training seconds (one thread; the median of its seeds' timings)
    whose mean is within 2x of the best, with those the timings cannot separate from it (``as_cheap``), and
    the kinds the seeds cannot separate from the best (their ranges overlap). A kind that failed on any seed
    (in training, or its rollout blew up) is left out of both choices, and named: its mean is over the seeds
    that did not, and a reader's own seed may fail as those did."""
    lines = ["", "### Which kind a chain requires (the card)", "",
             "The best of our kinds on the mean error at each N (the mean over seeds), and the one that is enough: "
             "of the kinds within 2x of the best, the one that trains in the fewest seconds (one thread; with "
             "several seeds, the median of the seeds' timings, and the kinds whose range of timings overlaps it, "
             "which cost the same as far as the timings can tell). With "
             "several seeds, the last column names the kinds whose seeds' range of errors overlaps the best's: "
             "the seeds cannot say which of them is better (with one seed it says nothing). A kind that failed on "
             "some seed (in training, or its rollout blew up) is left out of the choice (its mean is over the seeds "
             "that did not; another seed may fail as those did) and named in the last column.", "",
             "| N | best | enough (within 2x, fewest training s) | all within 2x | seeds cannot separate from the best "
             "| left out: failed (in training, or its rollout blew up) |",
             "| --- | --- | --- | --- | --- | --- |"]
    for name, row in results["rows"].items():
        if not name.startswith("chain"):
            continue
        kinds = results["meta"]["kinds"]
        measured = [kind for kind in kinds if "mean" in row.get(kind, {})]
        failed = {kind: row[kind]["failed"] for kind in measured if row[kind].get("failed")}
        means = {kind: row[kind]["mean"] for kind in measured if kind not in failed}
        left_out = ", ".join([f"{kind} ({len(why)} of {len(why) + len(row[kind]['seeds'])})"
                              for kind, why in failed.items()]
                             + [f"{kind} (every seed)" for kind in kinds
                                if {"diverged", "blew_up"} & set(row.get(kind) or {})]) or "none"
        if not means:
            if failed:
                lines.append(f"| {name[len('chain'):]} | every kind failed on some seed | | | | {left_out} |")
            continue
        best = min(means, key=means.get)
        near = [kind for kind in means if means[kind] <= 2 * means[best]]
        seconds = {kind: row["seconds"].get(kind, {}).get("seconds", float("inf")) for kind in near}
        enough = min(near, key=seconds.get)
        cheap = as_cheap(row["seconds"], enough, near)
        tied = inseparable(row, best, means) if len(row[best].get("seeds", ())) > 1 else None
        lines.append(f"| {name[len('chain'):]} | {best} {means[best]:.2e} | {enough} {means[enough]:.2e}, "
                     f"{seconds[enough]:.0f} s" + (f" (timings cannot tell it from {', '.join(cheap)})" if cheap else "")
                     + f" | {', '.join(sorted(near, key=means.get))} | "
                     f"{'one seed: not tested' if tied is None else ', '.join(tied) or 'none'} | {left_out} |")
    return lines


# our kinds that implement a published method of CHNN's table (Finzi et al. 2020): the same model, our code
SAME_METHOD = {"mechanical": "HNN", "constrained": "CHNN", "constrained_lagrangian": "CLNN"}


def beside(ours: dict, theirs: float) -> tuple[float, str]:
    """``(our mean / theirs, where our seeds stand)``: "below on every seed", "above on every seed", or
    "the seeds straddle it"; with one seed, "one seed: not tested"."""
    ratio = ours["mean"] / theirs
    if len(ours.get("seeds", ())) < 2:
        return ratio, "one seed: not tested"
    if ours["high"] < theirs:
        return ratio, "below on every seed"
    if ours["low"] > theirs:
        return ratio, "above on every seed"
    return ratio, "the seeds straddle it"


def against_published(results: dict, published: dict) -> list[str]:
    """Each of our kinds that implements a published method (``SAME_METHOD``) beside that method's published
    mean at each N: the ratio of our mean to theirs, whether it is within 2x, and where our seeds stand."""
    lines = ["", "### Our implementations of the published methods against their published means", "",
             "Their number is the paper's mean over its test starts; ours the mean over our seeds of each seed's "
             "mean. *Seeds*: whether every seed of ours is below their mean, every one above, or they straddle it.",
             "", "| N | method | published | ours | ours / published | within 2x | seeds |",
             "| --- | --- | --- | --- | ---: | --- | --- |"]
    rows = 0
    for name, row in results["rows"].items():
        if not name.startswith("chain"):
            continue
        n = int(name[len("chain"):])
        for kind, method in SAME_METHOD.items():
            ours, theirs = row.get(kind) or {}, published.get(n, {}).get(method)
            if theirs is None or "mean" not in ours:
                continue
            ratio, where = beside(ours, theirs[0])
            if ours.get("failed"):          # the mean is over the seeds that did not fail: say how many did
                where += (f"; {len(ours['failed'])} of {len(ours['failed']) + len(ours['seeds'])} failed "
                          "(in training, or the rollout blew up)")
            within = ("yes" if 1 / 2 <= ratio <= 2 else f"no: {1 / ratio:.1f}x below (better)" if ratio < 1
                      else f"no: {ratio:.1f}x above (worse)")
            lines.append(f"| {n} | {method} (ours: {kind}) | {theirs[0]:.2e} | {ours['mean']:.2e} | {ratio:.2f} | "
                         f"{within} | {where} |")
            rows += 1
    return lines if rows else []
