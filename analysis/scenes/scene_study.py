"""Which model does each scene need? Every model kind on every scene, measured.

    python analysis/scene_study.py --jobs 2                  # full study (reuses reproduce.py's runs)
    python analysis/scene_study.py --quick                   # smoke run (60 steps, a small grid)
    python analysis/scene_study.py --jobs 2 --update-docs    # docs/scenes.md, the README's model guide
    python analysis/scene_study.py --scenes 2body 3body --jobs 2 --update-docs   # two scenes, into the record
    python analysis/scene_study.py --data FILE --q x --v v   # your own measurements (measured_study.py)

The kinds are the ones each task trains (``--model``): the baseline MLP, the paper's HNN,
the separable HNN (H = T(p) + V(q)) and the dissipative HNN (J grad H + grad D); the pixel task
has its latent baseline and HNN. For every scene (spring, pend, real, 2body, 3body, pixels):

1. *Per kind* (width 200, all the data, ``--seeds`` seeds): test loss, energy MSE under each of
   the task's protocols, the rollout relative error (geometric mean over a horizon 10x the
   training trajectories') and the valid prediction time, beside the time over which the true
   system itself diverges from starts 1e-4 apart.
2. *Speed at equal accuracy* (seed 0; not pixels): the fastest ``hnn.rollout`` setting that
   reaches error 1e-4 against DOP853 rtol 1e-12 of the same field, and the learned H's drift over
   1000 periods (spring, pend) or 100 orbits (2body) at it and at the fastest symplectic one.
3. *Capacity and data* (spring, pend, 2body): hidden width x training fraction for every kind at
   ``--grid-seeds`` seeds (default: ``--seeds``; with ``--group`` a cell's seeds train as one group).
4. *Scene cards*: the smallest model (fewest parameters, then least data, then cheapest to train) whose mean over
   seeds is within 2x of the best mean energy MSE and the best mean rollout error of its scene,
   with the smaller models the seeds cannot separate from it, and per scene the kinds whose seeds
   overlap the best kind's; Pareto plots of error against training and rollout seconds.
5. *The real pendulum, the D-HNN paper's way*: their split and central differences, their energy
   2.4 (1 - cos q) + p^2, beside their published numbers.

Training goes through each task's ``train.py`` (as ``reproduce.py``, whose runs in ``<out>/runs``
are reused when the args match), in one sweep; the measuring is shared out over ``--jobs``
processes (``scene_measure``). Training seconds are each model's controlled cost
(``hnn_analysis.training_cost``), not the runs' recorded wall times. Writes ``<out>/scene_study.json`` (every number),
``<out>/scene_study.md`` and ``<out>/figures/scenes-pareto.png``.

The scenes of many bodies (gravity, lattice, lj: each declares the page ``bodies``) are a study of their own,
``--scenes gravity lattice lj``: the same stages (no grid, no long drift run), their cards in docs/bodies.md,
their files ``scene_study_bodies.*`` and ``figures/bodies-pareto.png``.

A page's whole study is longer than a sitting (docs/scenes.md: over two hours of training and one of measuring on
2 cores), so ``--update-docs`` keeps each scene's numbers in the page's record (``scene_record``,
its file in docs/, committed) and writes the page from it once every scene is there: study a page a
few scenes at a time, and its stamp names each sitting.
"""
from __future__ import annotations

import argparse
import sys

import hnn
from hnn_analysis import commands
from hnn_analysis.scenes import measured_inputs


def _parser() -> argparse.ArgumentParser:
    # torch loads here, with the study's modules: main reads a --data file's input before
    from hnn.sweeps import flags as sweep_flags
    from hnn_analysis.paper import study
    from hnn_analysis.scenes import scene_stages
    from hnn_analysis.scenes.scene_common import SEEDS, scenes

    p = hnn.cli.Parser(prog="scene_study.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="+", default=None, choices=scenes(None),
                   help="scenes to study (default: the paper's, every task that declares scene_study without a page of "
                        "its own; `--scenes gravity lattice lj`: the scenes of many bodies, docs/bodies.md)")
    quick = scene_stages.QUICK_STEPS, scene_stages.QUICK_WIDTHS, scene_stages.QUICK_FRACTIONS
    commands.add_flags(p, quick=f"smoke run: {quick[0]} steps per model (with --data: {study.QUICK_STEPS}, one width), "
                                f"widths {quick[1]} x fractions {quick[2]}, one seed unless --seeds, short drift runs (the run prints "
                                f"every cut); output in results-quick/; {commands.budget_words('scene_study')}; with "
                                f"--data: {commands.budget_words('scene_study --data')}",
                       out="output folder (default results/ or results-quick/)",
                       seeds=f"seeds of the per-kind rows and the grid's cells, or with --data of every model (default {SEEDS}; "
                            "--quick: 1)",
                       seeds_default=None,
                       jobs="training processes, as reproduce.py --jobs; then as many measuring processes (local "
                            "backend)")
    p.add_argument("--grid-seeds", type=hnn.settings.int_at_least(1), default=None,
                   help="seeds of every width x fraction cell, the cards' candidates (default: --seeds; 1 trains "
                        "the grid at seed 0 alone, a third of the cost, and the page says the cards rest on one seed)")
    sweep_flags.add_backend_flags(p)
    commands.add_flags(p, update_docs="write docs/scenes.md and the README's model guide (full settings only; with "
                                      "--scenes gravity lattice lj, docs/bodies.md's scene cards); with part of a page's "
                                      "scenes, put them in its record (a file in docs/, committed: each scene's last "
                                      "sitting) and write the page from the record once it holds them all; with --data, "
                                      "the README's row of that file")
    measured_inputs.add_flags(p)
    return p


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    inputs = measured_inputs.precheck(argv)     # a file's input errors answer before torch loads
    parser = _parser()
    from hnn.sweeps import flags as sweep_flags, sweep
    from hnn_analysis.scenes import measured_study, scene_report, scene_stages
    from hnn_analysis.scenes.scene_common import SEEDS, page_of, scenes

    args = parser.parse_args(argv)
    if args.update_docs and args.quick:
        parser.error("--update-docs writes full-settings results into docs/ and README.md; drop --quick")
    pages = sorted({page_of(task) for task in args.scenes or ()} or {"scenes"})
    if len(pages) > 1:
        parser.error(f"--scenes {' '.join(args.scenes)} mixes the scenes of the pages {', '.join(pages)}; a study "
                     "writes one page's cards: study " + " and ".join(
                         f"--scenes {' '.join(t for t in args.scenes if page_of(t) == page)}" for page in pages)
                     + " apart")
    page = pages[0]
    sweep_flags.check_backend(parser, args)
    given = args.seeds
    args.seeds = args.seeds or (1 if args.quick else SEEDS)
    if args.data:
        return measured_study.run(args, argv, parser, inputs)
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results")
    studied = args.scenes or (scene_stages.quick_scenes(scenes(page)) if args.quick else scenes(page))
    left_out = [task for task in scenes(page) if task not in studied] if args.quick and not args.scenes else []
    cuts = scene_stages.quick_cuts(studied, SEEDS, given or 1, left_out) if args.quick else []
    if cuts:
        commands.say_quick("scene_study", cuts)
    results, runs = scene_stages.run(args, argv, out, studied, cuts)
    scene_report.write(results, out, args.update_docs, page)
    sweep.exit_if_failed(runs)
    return results


if __name__ == "__main__":
    main()
