"""Does DGNet's init matter? The same rows of DGNet's protocol trained from their init (orthogonal
weights, zero biases) and from the original HNN's (orthogonal weights, torch's default biases), each
over the same seeds, side by side: ``python analysis/chains/dgnet.py --compare-init``, docs/dgnet.md's
sections ``dgnet-init-<task>``.

A row's two inits are told apart on the seeds alone: the two-sided Mann-Whitney U test of their
energy MSEs (no assumption on how the errors spread, which is far from normal: a seed can land 10x
off). Under ``P_SEPARATE`` the lower init is named; otherwise the section says the seeds cannot
separate them.
"""
from __future__ import annotations

import statistics

from scipy.stats import mannwhitneyu

from hnn_analysis import pages
from hnn_analysis.chains.dgnet_protocol import INIT_WORDS, ROWS, SETTINGS, spread_words, training_words
from hnn_analysis.provenance import machine

INITS = ("zero_bias", "orthogonal")          # theirs, then the original HNN's
TASKS = pages.DGNET_INIT_TASKS               # the tasks whose comparison docs/dgnet.md shows (section dgnet-init-<task>)
P_SEPARATE = 0.05                            # the rank test's two-sided p under which the seeds separate the inits


def compare(a: list[float], b: list[float]) -> tuple[float | None, str]:
    """(two-sided Mann-Whitney p, verdict) of energy MSEs ``a`` (zero biases) against ``b`` (default
    biases): which is lower where p < ``P_SEPARATE``, else that the seeds cannot separate them
    (and, with fewer than 3 seeds a side, that there are too few to test)."""
    if min(len(a), len(b)) < 3:
        return None, "too few seeds to test"
    p = float(mannwhitneyu(a, b, alternative="two-sided").pvalue)
    if p >= P_SEPARATE:
        return p, "the seeds cannot separate them"
    return p, "zero biases lower" if statistics.median(a) < statistics.median(b) else "default biases lower"


def _cell(values: list[float]) -> str:
    return f"{statistics.mean(values):.2e} ({spread_words(values)})"


def init_table(results: dict, task: str) -> str:
    """Section ``dgnet-init-<task>`` of ``results`` (``dgnet.json`` of a ``--compare-init`` run)."""
    meta, rows = results["meta"], results["init_rows"][task]
    n = results["seeds"]
    trained = training_words([run for by_init in rows.values() for runs in by_init.values() for run in runs])
    lines = [f"### {task}: their init against the original HNN's", "",
             pages.generated_by(meta, f"{machine(meta)}, one torch thread a run")
             + f", {meta['seconds']:.0f} s{trained}: {n} seeds a row and init, {results['steps'][task]} steps a run "
             f"(theirs: {SETTINGS[task]['steps']}). Zero biases: {INIT_WORDS['zero_bias']}; default biases: "
             f"{INIT_WORDS['orthogonal']}. Energy MSE over the seeds: mean (median, min, max); p: two-sided "
             f"Mann-Whitney U of the two inits' seeds, which the seeds separate under p = {P_SEPARATE:g}.", "",
             "| row (train / predict) | zero biases | default biases | p | verdict |", "| --- | --- | --- | ---: | --- |"]
    for label, by_init in rows.items():
        for predict in ROWS[label][3]:
            a, b = ([r["energy"][predict] for r in by_init[init]] for init in INITS)
            p, verdict = compare(a, b)
            lines.append(f"| {label} ({ROWS[label][2]} / {predict}) | {_cell(a)} | {_cell(b)} | "
                         f"{'' if p is None else f'{p:.2g}'} | {verdict} |")
    return "\n".join(lines)
