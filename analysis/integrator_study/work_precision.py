"""Work-precision of the adaptive solvers on learned fields: ours (``hnn.rollout``'s ``dopri5`` and
``dop853``) beside torchdiffeq's and scipy's, compared at equal error, not at equal tolerance.

    python analysis/integrator_study/work_precision.py --quick        # the learned spring HNN, 3 tolerances
    python analysis/integrator_study/work_precision.py --update-docs  # docs/integrators.md and its figures

On the integrator study's tasks (spring, pend, 2body, 3body: its horizons and start states,
``TaskSpec.integrator_study``) and their saved HNN and baseline (``<runs>/<task>-<kind>-seed0``, as
``analysis/reproduce.py`` trains them; a task without them is skipped, saying so), in float64 on one
torch thread, for a batch of 64 start states and for the first of them alone: every solver at every
tolerance of a ladder (rtol = atol, 1e-3 .. 1e-11 in half decades), timed in rounds (each round runs
every solver and tolerance once; the median over rounds is kept), and scored by the max error
against scipy's DOP853 at rtol = atol = 1e-13 on the same field. Each timed run also counts the
field's calls and the seconds spent inside them (``field_s``): the rest is the solver's own work.
The same process times one field call alone at each batch size (``call_us``): the floor a solver
making ``calls`` calls cannot go under.

The equal-error comparison (``work_precision_report``): at every half decade of error that both
curves reach, each solver's seconds there, interpolated log-log along its Pareto front (the cheapest
settings for their error), and the ratio peer / ours. ``why``: the issue's measurement (the learned
spring HNN, 64 starts uniform in [-1, 1]^2, t in [0, 30]) taken apart: the error norm, the error
estimator and the output times, one at a time.

Writes ``<out>/work_precision.json`` and ``.md``, ``<out>/work-precision-<task>.png`` (each model and batch)
and ``<out>/work-precision.png`` (the HNN on every task); ``--update-docs`` also the ``work-precision``
section of docs/integrators.md and that last figure in docs/figures/.
"""
from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import hnn
from hnn.settings import int_at_least
from hnn.io import atomic_write
from hnn_analysis import commands
from hnn_analysis.integrator_study import peer_solvers
from hnn_analysis.integrator_study.work_precision_measure import MODELS, QUICK_RTOLS, RTOLS, TASKS, measure_task, why
from hnn_analysis.integrator_study.work_precision_report import markdown, overview, plot, why_table
from hnn_analysis.provenance import cpu_snapshot, others_load, provenance


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=None, choices=TASKS, help=f"tasks (default: {' '.join(TASKS)})")
    p.add_argument("--runs", type=Path, default=None, help="saved runs (default <repo>/results/runs)")
    commands.add_flags(p, out="output folder (default <repo>/results/work_precision)",
                       quick="the spring HNN alone, 3 tolerances, one round, no why table")
    p.add_argument("--repeats", type=int_at_least(1), default=3, help="timed rounds (the median is kept)")
    commands.add_flags(p, update_docs="write the work-precision section of docs/integrators.md and its figures")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = p.parse_args(argv)
    if args.update_docs and args.quick:
        p.error("--update-docs writes the full ladder into docs/integrators.md; drop --quick")
    root = hnn.tasks.repo_root()
    runs = args.runs or root / "results" / "runs"
    out = args.out or root / "results" / ("work_precision-quick" if args.quick else "work_precision")
    tasks = args.tasks or (("spring",) if args.quick else TASKS)
    missing = [peer.name for peer in peer_solvers.PEERS.values() if not peer.available()]
    notes = [f"{name}: not installed (pip install -e '.[bench]'); left out" for name in missing]
    start, load_start = time.perf_counter(), cpu_snapshot()
    results = {"rows": [], "notes": notes}
    for task in tasks:
        tic = time.perf_counter()
        results["rows"] += measure_task(task, runs, QUICK_RTOLS if args.quick else RTOLS,
                                        1 if args.quick else args.repeats, notes, ("hnn",) if args.quick else MODELS)
        print(f"{task}: {time.perf_counter() - tic:.0f} s", flush=True)
    results["why"] = None if args.quick else why(runs)
    results["meta"] = {**provenance(), "command": commands.portable_command(argv, "analysis/integrator_study/work_precision.py"),
                       "mode": "quick" if args.quick else "full", "seconds": time.perf_counter() - start,
                       "others_load": others_load(load_start, cpu_snapshot()), "peers": peer_solvers.versions(),
                       "repeats": 1 if args.quick else args.repeats, "out": commands.portable_path(out)}
    for task in dict.fromkeys(r["task"] for r in results["rows"]):
        plot(task, [r for r in results["rows"] if r["task"] == task], out / f"work-precision-{task}.png")
    figure = overview(results["rows"], out / "work-precision.png") if results["rows"] else None
    why_text = "\n" + why_table(results["why"]) if results["why"] else ""
    text, section = markdown(results) + why_text, markdown(results, detail=False) + why_text
    # a page is written only from a whole ladder: a missing run would drop its rows from docs/integrators.md
    absent = [f"{task} {model}" for task in tasks for model in (("hnn",) if args.quick else MODELS)
              if not any((r["task"], r["model"]) == (task, model) for r in results["rows"])]
    commands.publish(out, "work_precision", results, text,
                     {"work-precision": section} if args.update_docs and not absent else {})
    if args.update_docs and absent:
        p.error(f"--update-docs: no saved run of {', '.join(absent)} in {runs}, so docs/integrators.md was left as "
                f"it is (this run's tables are in {out}); train them (python analysis/reproduce.py) or point --runs "
                "at the folder that holds them")
    if args.update_docs and figure is not None:         # the page shows the HNN's panels; each task's are in out
        atomic_write(root / "docs" / "figures" / figure.name, lambda tmp: shutil.copyfile(figure, tmp))
    print(f"total {results['meta']['seconds']:.0f} s; wrote {out}")
    return results


if __name__ == "__main__":
    main()
