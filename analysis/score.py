"""Score a saved run (or every run under a folder) as the tables and cards do, and draw it.

    python analysis/score.py results/runs/spring-hnn-seed0-cbac7a2b          # one run
    python analysis/score.py results-quick/runs                               # every run under a folder
    python analysis/score.py RUN --plot [--out DIR]                           # and its figures

For a run of one of the tasks it prints what docs/results.md and docs/scenes.md report of that run:

- **test loss**: the derivative MSE on the held-out rows (± std / sqrt(rows)), as its ``train.py`` saved it;
- **energy MSE** under each of the task's protocols, by name (``paper``, ``corrected``): the tables' numbers
  (``hnn.evaluate_energy``, every trial of the protocol);
- **rollout error** and **valid time** by the scene cards' protocol: the model rolled out from 8 starts over
  10 training lengths (``hnn.evaluation.rollout_errors``, dopri5 rtol 1e-6 in float64) against the truth
  (DOP853 rtol 1e-12), the geometric mean of the relative error and the median time it stays under 0.1,
  beside the time over which the truth itself diverges from starts 1e-4 apart.

The code is the scene study's own (``scene_common.Scene.measure``), so a run the study measured scores the
same here (``tests/test_score.py``). For a run of ``experiment-measured`` (your own file) it prints the
measured card's numbers instead (``measured_metrics``): the prediction error at ``--horizon`` beside the
naive extrapolation's, the valid time, and with ``--energy`` the energy drift; the file must still be where
the run read it.

``--plot`` draws the run's figures from the run alone (into ``--out``, default ``RUN/figures``): the field
and a trajectory against the truth (1-D tasks), the orbits (2-body, 3-body), the frames (pixels), the
energy over time under every protocol (a learned map, which has no field: its energy over its own steps);
for a measured run the held-out tails against its prediction. With a folder, one figure per data file also
sets each kind's best run beside the others.

A run is named by what it is: its kind, with ``+<fit>`` where a least-squares ``--fit`` found its weights
(``hnn+library``, as its folder: ``hnn.runs.kind_label``), in the table and the figures ("Hamiltonian NN
(library fit)"). A folder is scored run by run: a run that cannot be scored (an unfinished save, a file
gone) is named and the others go on; the command then ends with one ``error:`` line listing them (exit
code 1), after writing ``score.json`` (``"not_scored"``: each one's reason). One unfinished run is one
``error:`` line with the fix (exit code 2).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import hnn
from hnn.io import write_json
from hnn_analysis.scenes.scoring import describe, plot_kinds, plot_score, run_folders, score_run, table, task_of


def _parser():
    p = hnn.cli.Parser(prog="score.py", description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", type=Path, metavar="RUN_OR_FOLDER", help="a saved run folder, or a folder of them")
    p.add_argument("--plot", action="store_true", help="draw each run's figures too (into --out)")
    p.add_argument("--out", type=Path, default=None,
                   help="where the figures and score.json go (default: RUN/figures for one run, FOLDER/score for a "
                        "folder)")
    p.add_argument("--task", default=None, help="the runs' task, where a run's name does not tell it")
    p.add_argument("--horizon", type=hnn.settings.positive_float, default=None,
                   help="measured runs: seconds ahead of the prediction error (default, as the study: a tenth of the "
                        "shortest held-out tail)")
    p.add_argument("--energy", default=None, help="measured runs: an energy of the file's columns, as the study's --energy")
    return p


def main(argv=None) -> list[dict]:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser()
    args = parser.parse_args(argv)
    try:                # the input, checked before torch loads
        folders = run_folders(args.runs)
        if args.task is not None and args.task not in hnn.tasks.task_names():
            raise ValueError(f"--task {args.task}: no such task here; choose from {' '.join(hnn.tasks.task_names())}")
        single = len(folders) == 1 and folders[0] == args.runs
        if single:
            _check_complete(folders[0])
        tasks = {folder: args.task or task_of(json.loads((folder / "args.json").read_text())) for folder in folders}
    except (OSError, ValueError) as err:
        parser.error(str(err))
    out = args.out or (args.runs / "figures" if single else args.runs / "score")
    print(f"score: {len(folders)} run{'s' if len(folders) != 1 else ''} under {args.runs}", flush=True)
    scores, failed, start = [], {}, time.perf_counter()
    for n, folder in enumerate(folders, 1):
        try:        # run by run: one that cannot be scored or drawn is named, and the others go on
            if not single:
                _check_complete(folder)
            score = _score(folder, tasks[folder], args)
            scores.append(score)
            print(f"[{n}/{len(folders)}, {time.perf_counter() - start:.0f} s] " + describe(_named(score))
                  + f"\n  ({score['seconds']:.1f} s)", flush=True)
            if args.plot:
                drawn = plot_score(score, out if single else out / folder.name, args.horizon)
                print(f"  figures: {', '.join(str(p) for p in drawn)}", flush=True)
        except Exception as err:        # named and counted: a folder's other runs still score
            failed[folder] = hnn.cli.one_line(f"{type(err).__name__}: {err}")
            print(f"[{n}/{len(folders)}] {folder}: not scored: {failed[folder]}", flush=True)
    if len(scores) > 1:
        print("\n" + table([_named(s) for s in scores]))
        if args.plot:
            for path in plot_kinds(scores, out, args.horizon):
                print(f"figure of every kind: {path}")
    if scores and (args.out is not None or not single):
        write_json(out / "score.json", {"runs": scores, "not_scored": {str(k): v for k, v in failed.items()}})
        print(f"wrote {out / 'score.json'}")
    if failed:
        parser.exit(1, f"error: {len(failed)} of {len(folders)} runs not scored: "
                       + "; ".join(f"{folder.name}: {why}" for folder, why in failed.items()) + "\n")
    return scores


def _check_complete(folder: Path) -> None:
    """A ValueError with the fix where ``folder`` lacks its completion mark (an interrupted save)."""
    from hnn.runs import COMPLETE, is_complete
    if not is_complete(folder):
        raise ValueError(f"{folder} is not a complete run: it lacks {COMPLETE} or a file that lists, so its save was "
                         "interrupted; run its train.py again with the same settings (it resumes or retrains) or "
                         "delete the folder")


def _score(folder: Path, task: str, args) -> dict:
    """``score_run``'s numbers of one run, with its ``fit`` (args.json's: how its weights were found)."""
    score = score_run(folder, task, args.horizon, args.energy)
    score["fit"] = json.loads((folder / "args.json").read_text()).get("fit", "adam")
    return score


def _named(score: dict) -> dict:
    """``score`` with its kind as runs are named by what they are (``hnn.runs.kind_label``: ``hnn+library``)."""
    from hnn.runs import kind_label
    return {**score, "kind": kind_label(score["kind"], score.get("fit"))}


if __name__ == "__main__":
    main()
