"""The benchmark's report: the table of ours against the original's way, the training ratio's ceiling at
the step's floor, and docs/speed.md's section, whose group part a ``--jobs group`` run rewrites alone.
"""
from __future__ import annotations

import torch

import hnn
from hnn_analysis import pages
from hnn_analysis.benchmarks.benchmark_jobs import LABELS


def jobs_table(results: dict, steps: int, trials: int) -> str:
    lines = ["| job | ours (median s) | original style (median s) | original / ours | check | result |",
             "| --- | ---: | ---: | ---: | --- | --- |"]
    for job, r in results.items():
        checks = "; ".join(f"{c['name']} = {c['value']:.3g} (tol {c['tolerance']:g})" for c in r["checks"])
        verdict = "pass" if all(c["passed"] for c in r["checks"]) else "FAIL"
        lines.append(f"| {LABELS[job].format(steps=steps + 1, trials=trials)} | {r['median_ours']:.3f} | "
                     f"{r['median_original']:.3f} | {r['ratio_original_over_ours']:.1f}x | {checks} | {verdict} |")
    return "\n".join(lines)


def ceiling(results: dict, floors: dict | None, steps: int) -> str:
    """What ``original / ours`` for training would be with our step exactly at its floor (same threads)."""
    r = (floors or {}).get("spring", {}).get("by_threads", {}).get(str(torch.get_num_threads()))
    if "train" not in results or r is None:
        return ""
    at_floor = (steps + 1) * r["floor_ms"] / 1e3
    return (f"Training ratio ceiling: the original-style loop ({results['train']['median_original']:.2f} s) over "
            f"{steps + 1} steps at the spring step's floor ({at_floor:.2f} s) is "
            f"{results['train']['median_original'] / at_floor:.1f}x: no implementation of the same six products "
            "per step can beat that.")


GROUP_MARK = "<!-- the group job's part: `--jobs group --update-docs` rewrites it alone -->"


def benchmark_section(main: str | None, group: str | None) -> str:
    """The generated section of docs/speed.md: ``main`` (the other jobs' tables under their stamp),
    then ``GROUP_MARK`` and ``group`` (the group table under its own); None keeps that part as it is."""
    page = hnn.tasks.repo_root() / pages.PAGES["benchmark"]
    begin, end = "<!-- benchmark:begin -->", "<!-- benchmark:end -->"
    content = page.read_text() if page.exists() else ""
    current = content.split(begin, 1)[1].split(end, 1)[0].strip() if begin in content and end in content else ""
    old_main, _, old_group = current.partition(GROUP_MARK)
    main = (old_main if main is None else main).strip()
    group = (old_group if group is None else group).strip()
    return main + (f"\n\n{GROUP_MARK}\n\n{group}" if group else "")
