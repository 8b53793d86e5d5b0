"""Every analysis command's ``--quick`` from nothing, timed against its budget (docs/speed.md), and a reader's
first hour beside them: ``pytest``, its first check ``pytest -m quick``, and the Python of the README and of
docs/python.md as written.

    python analysis/benchmarks/quick_budgets.py                        # all of them, one at a time
    python analysis/benchmarks/quick_budgets.py --only reproduce peers # some
    python analysis/benchmarks/quick_budgets.py --update-docs          # the quick-budgets section of docs/speed.md

A benchmark, not a test: it prints a table and writes JSON, and passes or fails nothing. Each
command runs as a reader's first run of it would: in a subprocess, one after another, with its
output in a fresh temporary folder and its tasks read from a fresh clone of this checkout's commit
(``HNN_REPO`` points there), so that no run and no dataset is cached. The budgets are
``hnn_analysis.commands.QUICK_BUDGETS``, each written in its command's ``--help``. Beside every time
stand the machine's load averages (``os.getloadavg``) just before and just after, and the cores that
other processes kept busy in the second before it started: a time on a busy box says little about a
quiet one. Beside each quick mode that has one stands its plan on the reference box (``reference_plans``: its
stages at their declared costs, what tests/test_plan.py holds within the budget), and each of its stages against
the seconds the command recorded for it (``stage_ratios``: the plan's target is each within 1.5x). ``--out`` gets
``quick_budgets.json`` and each command's log.
"""
from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from pathlib import Path

import hnn
from hnn.io import write_json
from hnn_analysis import commands, pages
from hnn_analysis.benchmarks.timed_commands import COMMANDS, verdict, run_one, section
from hnn_analysis.provenance import provenance


def reference_plans() -> dict:
    """``{command name: its stages on the reference box}`` (``hnn_analysis.plan``: declared costs, nothing run)."""
    from hnn_analysis.chains import peer_plan
    from hnn_analysis.paper import study
    from hnn_analysis.scenes import scene_stages
    return {"reproduce": study.reference_plan(study.quick_tasks(hnn.tasks.paper_tasks())),
            "scene_study": scene_stages.reference_plan(), "peers": peer_plan.reference_plan()}


# what each quick mode records of its stages' seconds (timed_commands.recorded_seconds), as the stages of its plan:
# (the plan's stages, what the command timed, its seconds from the recorded ones); the plan's target is each within
# PLAN_FACTOR of its time on a quiet box (issue 79)
PLAN_FACTOR = 1.5
STAGES = {
    "reproduce": [(("plan", "build"), "its datasets built and its configs timed, before the training",
                   lambda s: s["total"] - s["training"] - s["evaluation"]),
                  (("train",), "the training", lambda s: s["training"]),
                  (("evaluate",), "the evaluation and figures", lambda s: s["evaluation"])],
    "scene_study": [(("plan", "build"), "its datasets built and its configs timed, before the training",
                     lambda s: s["training"] - s["sweep"]),
                    (("train",), "the training", lambda s: s["sweep"]),
                    (("measure",), "the measuring", lambda s: s["measure"])],
    # peers.py measures each run as it finishes training, inside the training's wall time
    "peers": [(("train",), "the training", lambda s: s["training"] - s["measuring"]),
              (("measure",), "the runs' measuring", lambda s: s["measuring"]),
              (("time",), "the table's timing of the kinds", lambda s: s["timing"])]}


def stage_ratios(name: str, plan: dict, seconds: dict) -> list[dict]:
    """``name``'s plan on the reference box (``{stage: seconds}``) against the stages' seconds its run recorded:
    ``[{"stages", "what", "plan", "measured", "ratio"}]`` (ratio: plan / measured), [] where it recorded none."""
    rows = []
    for stages, what, measured in STAGES.get(name, ()):
        try:
            took = measured(seconds)
        except KeyError:        # a command that recorded other stages (an older one, a failed run): no ratio
            return []
        planned = sum(plan[stage] for stage in stages)
        rows.append({"stages": list(stages), "what": what, "plan": planned, "measured": took,
                     "ratio": planned / took if took > 0 else None})
    return rows


def _ratios_section(runs: list[dict]) -> str:
    """The Markdown table of each quick mode's plan on the reference box beside its stages' measured seconds."""
    lines = [f"Each quick mode's plan on the reference box (`hnn_analysis.plan`: declared costs, what tests/test_plan.py "
             f"holds within the budget) beside the seconds its run above recorded for each stage; the target is a "
             f"ratio within {1 / PLAN_FACTOR:.2g}-{PLAN_FACTOR:g} on a quiet box.", "",
             "| command | plan's stages | what the run timed | plan (s) | measured (s) | plan / measured |",
             "| --- | --- | --- | ---: | ---: | ---: |"]
    for row in runs:
        for stage in row.get("stage_ratios", ()):
            ratio = "n/a" if stage["ratio"] is None else f"{stage['ratio']:.2f}"
            lines.append(f"| {row['command']} | {' + '.join(stage['stages'])} | {stage['what']} | {stage['plan']:.1f} "
                         f"| {stage['measured']:.1f} | {ratio} |")
    return "\n".join(lines) if len(lines) > 4 else ""


def main(argv=None) -> dict:
    p = hnn.cli.Parser(prog="quick_budgets.py", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--only", nargs="+", choices=list(COMMANDS), metavar="NAME", default=None,
                   help=f"run these only (default: all): {', '.join(repr(n) for n in COMMANDS)}")
    p.add_argument("--out", type=Path, default=None,
                   help="folder of quick_budgets.json and the commands' logs (default results/quick_budgets)")
    p.add_argument("--update-docs", dest="update_docs", action="store_true",
                   help="write the quick-budgets section of docs/speed.md (every command only)")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = p.parse_args(argv)
    if args.update_docs and args.only:
        p.error("--update-docs writes the table of every command; drop --only")
    root = hnn.tasks.repo_root()
    out = args.out or root / "results" / "quick_budgets"
    out.mkdir(parents=True, exist_ok=True)
    names = args.only or list(COMMANDS)
    meta = {**provenance(), "command": commands.portable_command([shlex.quote(a) for a in argv],
                                                                 "analysis/benchmarks/quick_budgets.py")}
    runs, tic, planned = [], time.perf_counter(), reference_plans()
    for i, name in enumerate(names, 1):
        print(f"[{i}/{len(names)}, {time.perf_counter() - tic:.0f} s] {name}: python {' '.join(COMMANDS[name])} "
              "(from nothing) ...", flush=True)
        row = run_one(name, root, out)
        if name in planned:
            row["reference_plan"] = {stage.what: stage.seconds for stage in planned[name]}
            row["stage_ratios"] = stage_ratios(name, row["reference_plan"], row.get("seconds", {}))
        runs.append(row)
        print(f"  {row['wall']:.1f} s against a budget of {row['budget']} s: {verdict(row)}; load "
              f"{row['load_before'][0]:.2f} before, {row['load_after'][0]:.2f} after; log {row['log']}", flush=True)
        if name in planned:
            print(f"  its plan on the reference box: {sum(row['reference_plan'].values()):.0f} s ("
                  + ", ".join(f"{what} {seconds:.0f} s" for what, seconds in row["reference_plan"].items()) + ")",
                  flush=True)
            for stage in row["stage_ratios"]:
                ratio = "n/a" if stage["ratio"] is None else f"{stage['ratio']:.2f}x"
                print(f"    {' + '.join(stage['stages'])}: plan {stage['plan']:.1f} s, {stage['what']} "
                      f"{stage['measured']:.1f} s: {ratio}", flush=True)
    result = {"meta": meta, "omp_num_threads": os.environ.get("OMP_NUM_THREADS"), "runs": runs}
    write_json(out / "quick_budgets.json", result)
    text = section(result)
    ratios = _ratios_section(runs)
    if ratios:
        text += "\n\n" + ratios
    print("\n" + text + f"\n\nwrote {out / 'quick_budgets.json'}")
    if args.update_docs:
        print(f"updated {pages.update_section('quick-budgets', text)}")
    failed = [row["command"] for row in runs if row["returncode"] != 0]
    if failed:      # a time of a command that failed means nothing: say so with the exit code
        print(f"{', '.join(failed)} failed: see the logs above", file=sys.stderr)
        raise SystemExit(1)
    return result


if __name__ == "__main__":
    main()
