"""The speed / accuracy trade of every integrator, on the true systems and on the trained models.

    python analysis/integrator_study/speed_accuracy.py                       # every task, full grid (a few minutes)
    python analysis/integrator_study/speed_accuracy.py --quick               # fewer settings (well under a minute)
    python analysis/integrator_study/speed_accuracy.py --runs results/runs --update-docs

For each task with a true dynamics function (spring, pend, 2body, 3body) and each saved model
(the HNN and the baseline that ``analysis/reproduce.py`` trains into ``<runs>/<task>-<label>-seed0``;
a model not found is skipped, saying so), every method x setting x dtype is timed (median of a
few repeats of one batched ``hnn.rollout``) and scored against a float64 DOP853 rtol 1e-12
reference of the same field (the model's own field for a model):

- error: max |x(t) - x_ref(t)| over the batch and the output times;
- energy drift: max |H(t) - H(0)| with the system's H (the true system and the baseline) or the
  model's learned H (the HNN);
- nfev: batched evaluations of the field.

Beside ours, the peers' adaptive solvers a user would otherwise call, at the same tolerances and on
the same fields: scipy's RK45 and DOP853 (through ``hnn.rollout``'s ``solve_ivp``) and torchdiffeq's
``dopri5`` and ``dopri8`` (``peer_solvers``; the ``bench`` extra, left out with a note where it is not
installed; the versions are recorded). ``work_precision.py`` compares them at equal error.

Settings: rtol 1e-3 .. 1e-12 for the adaptive methods (with atol = rtol; in float32 only rtol >=
100 eps, tighter ones would only warn), dt over two decades for the fixed-step ones on the true
systems and over the coarse decade on the models (each model call costs 5-10x a true one).
``--quick`` takes 2 tolerances, 3 (models: 2) step sizes, one repeat, spring / pend / 2body. Leapfrog
(and yoshida4 on it) is run only on the true systems, whose H is separable; models use the
midpoint base. Then the extremes: 10^3 spring periods, the pendulum at its separatrix and over
the top, steps past each method's stability limit, and the learned models far outside their
training data. Writes ``<out>/speed_accuracy.json``, ``<out>/speed_accuracy.md`` and
``<out>/summary.md`` (the table of docs/integrators.md) and ``<out>/pareto-<task>.png`` (error vs seconds, log-log, one line per method and dtype).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import hnn
from hnn.io import atomic_write
from hnn_analysis import commands, plan
from hnn_analysis.integrator_study import peer_solvers
from hnn_analysis.integrator_study.speed_measure import STUDY_PEERS, extremes, measure_task, study_settings
from hnn_analysis.integrator_study.speed_report import markdown, pareto_plot, summary_markdown
from hnn_analysis.provenance import provenance


def main(argv=None) -> dict:
    p = hnn.cli.Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=None, help="tasks (default: every task with true dynamics)")
    p.add_argument("--runs", type=Path, default=None, help="saved runs (default <repo>/results/runs)")
    commands.add_flags(p, out="output folder (default <repo>/results/speed_accuracy)",
                       quick="fewer settings, one repeat, shorter extremes")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats per setting (median)")
    commands.add_flags(p, update_docs="write the generated section of docs/integrators.md")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = p.parse_args(argv)
    root = hnn.tasks.repo_root()
    runs = args.runs or root / "results" / "runs"
    out = args.out or root / "results" / "speed_accuracy"
    notes = [f"{peer}: not installed (pip install -e '.[bench]'); its rows are left out"
             for peer in STUDY_PEERS if not peer_solvers.PEERS[peer].available()]
    if not runs.is_dir():
        notes.append(f"no runs folder {runs}: learned models skipped (train them with analysis/reproduce.py)")
        runs = None
    measurable = [t for t in hnn.available_tasks() if study_settings(t) is not None]
    tasks = args.tasks or [t for t in measurable if study_settings(t).get("quick") or not args.quick]
    for task in hnn.available_tasks():
        if task not in measurable:
            notes.append(f"{task}: no true dynamics function in its data.py; not measured")
    for task in tasks:
        if task not in measurable:
            raise SystemExit(f"task {task!r} has no true dynamics to measure; choose from {measurable}")
    plan.say("speed_accuracy", [plan.Stage("measure", len(tasks), "tasks' true and learned fields at every setting"),
                                plan.Stage("extremes", 1, "set of extreme cases")])
    start, ahead = time.perf_counter(), plan.Ahead(len(tasks))
    results = {"tasks": {}, "notes": notes}
    for done, task in enumerate(tasks, 1):
        t0 = time.perf_counter()
        results["tasks"][task] = measure_task(task, runs, args.quick, 1 if args.quick else args.repeats, notes)
        print(f"{task}: {time.perf_counter() - t0:.1f} s{ahead.tag(done)}", flush=True)
        pareto_plot(task, results["tasks"][task], out / f"pareto-{task}.png")
    results["extremes"] = extremes(args.quick, runs, notes)
    results["meta"] = {**provenance(), "command": commands.portable_command(argv, "analysis/integrator_study/speed_accuracy.py"),
                       "mode": "quick" if args.quick else "full grid", "seconds": time.perf_counter() - start,
                       "peers": peer_solvers.versions(),
                       "out": commands.portable_path(out)}
    summary = summary_markdown(results)
    atomic_write(out / "summary.md", lambda tmp: Path(tmp).write_text(summary))
    commands.publish(out, "speed_accuracy", results, markdown(results),
                     {"speed-accuracy": summary} if args.update_docs else {})
    print(f"total {results['meta']['seconds']:.1f} s; wrote {out} (the summary: {out / 'summary.md'})")
    return results


if __name__ == "__main__":
    main()
