"""The peers' published numbers on pendulum chains beside ours, on their own protocols (docs/peers.md).

    python analysis/peers.py --jobs 2 --update-docs      # the whole table, 5 seeds (about 20 hours on 2 cores)
    python analysis/peers.py --device cuda --update-docs # the same on a GPU, each row's seeds as one group
    python analysis/peers.py --quick                      # a smoke run: small data, few steps, N = 1, 2
    python analysis/peers.py --seed 3 --seeds 1 --train-only --out DIR   # one seed's runs, over sittings
    python analysis/peers.py --record-only --out DIR      # record a stopped sitting's finished runs
    python analysis/peers.py --train-only --only 'chain1/*' --jobs 2     # part of it: a machine's or a sitting's share

Trains our model kinds (``kinds()``: every registered one that reads the chain's observed states, from
``hnn.MODEL_KINDS``, so a new kind reaches the table with no edit here) with ``experiment-chain/train.py``'s config on CHNN's protocol (Finzi et al. 2020) for
N = 1, 2, 3, 5 bobs, and on the LNN double pendulum (Cranmer et al. 2020), through
``hnn/sweeps/sweep.py`` (a rerun reuses every run of the same config); then measures each on its
protocol (``experiment-chain/protocols.py``): CHNN's geometric-mean relative error of the
Cartesian rollout (dopri5 at rtol 1e-7, in float64), mean and median over the test starts, with
the chaos floor; LNN's energy error at T = 100 s. A rollout that blows up is reported by name
with its time, never as a NaN. Each run's numbers go into the record (``peer_record``: the full
table's is docs/peers-runs.json, committed) as soon as it is measured, and the table is built from
the record: a run recorded is neither trained nor measured again, even on another machine. Writes ``peers.json`` and ``peers.md`` under ``--out``;
``--update-docs`` puts the table into docs/peers.md (full settings only).
"""
from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import hnn
from hnn.io import atomic_write
from hnn_analysis import commands, pages
from hnn.sweeps import flags as sweep_flags, sweep
from hnn_analysis.chains import peer_record
from hnn_analysis.chains.peer_measure import add_seconds, curves_figure, over_seeds
from hnn_analysis.chains.peer_plan import FULL, FULL_SEEDS, QUICK, kinds, plan_seeds, quick_cuts, select
from hnn_analysis.chains.peer_table import markdown
from hnn_analysis.commands import portable_command
from hnn_analysis.provenance import provenance


def _parser() -> argparse.ArgumentParser:
    p = hnn.cli.Parser(prog="peers.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands.add_flags(p, quick="a smoke run of every stage: small data, 100 steps (the LNN too), N = 1, 2; "
                       + commands.budget_words("peers"),
                       out="output folder (default: results/peers, or results-quick/peers with --quick)",
                       jobs="worker processes of the training and of the seeds' rollouts (1: in this process)")
    p.add_argument("--seed", type=hnn.settings.int_at_least(0), default=0, help="the first seed")
    p.add_argument("--seeds", type=hnn.settings.int_at_least(1), default=None,
                   help="seeds seed .. seed + seeds - 1 of every run, the tables' means over them with their range "
                        f"(default: {FULL_SEEDS} for the full table, 1 with --quick)")
    p.add_argument("--train-only", action="store_true",
                   help="train the runs still missing, measure each into the record (--record), and stop before "
                        "the table: a table trained over several sittings or machines (e.g. one seed each, --seed K "
                        "--seeds 1) is written by the same command without this flag, from the record")
    p.add_argument("--record", type=Path, default=None,
                   help="the record of measured runs that the table is built from: a run recorded there is neither "
                        "trained nor measured again (default: docs/peers-runs.json for the full table, committed, "
                        "so a table trained over sittings or machines keeps each finished run; OUT/peers-runs.json "
                        "otherwise); a new path starts a record of your own")
    p.add_argument("--record-only", action="store_true",
                   help="train nothing: measure the saved runs under --out that the record lacks, add them, and "
                        "stop (a sitting whose training was stopped keeps what it finished)")
    p.add_argument("--only", action="append", metavar="PATTERN", default=None,
                   help="with --train-only, only the runs whose name matches (shell pattern, repeatable: 'chain1/*', "
                        "'*/lagrangian/seed[12]'): a table split over machines, or what fits a sitting")
    sweep_flags.add_backend_flags(p)
    commands.add_flags(p, update_docs="write the table into docs/peers.md (full settings only)")
    return p


def main(argv=None, settings: dict | None = None) -> dict:
    """Train, measure, write; ``settings`` replaces ``FULL`` / ``QUICK`` (the tests' tiny config)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser()
    args = parser.parse_args(argv)
    if args.update_docs and (args.quick or settings is not None):
        parser.error("--update-docs writes full-settings results into docs/peers.md; drop --quick")
    if args.update_docs and args.train_only:
        parser.error("--train-only stops before the table that --update-docs writes; drop one of them")
    if args.record_only and (args.train_only or args.update_docs):
        parser.error("--record-only only records saved runs: drop --train-only and --update-docs")
    if args.only and not args.train_only:
        parser.error("--only trains part of the table: add --train-only (the table is built from the whole record)")
    sweep_flags.check_backend(parser, args)
    full = settings is None and not args.quick
    declared = settings is None and args.quick      # --quick's own settings: its declared costs hold (peer_plan)
    settings = {"kinds": kinds(), **(settings or (QUICK if args.quick else FULL))}
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results") / "peers"
    cuts = quick_cuts(settings) if args.quick and not full else []
    if cuts:
        commands.say_quick("peers", cuts)
    seeds = range(args.seed, args.seed + (args.seeds or (FULL_SEEDS if full else 1)))
    path = args.record or (hnn.tasks.repo_root() / peer_record.RECORD if full else out / "peers-runs.json")
    try:
        jobs = select(plan_seeds(settings, out, seeds), args.only)
        record = peer_record.load(path, settings)
    except ValueError as err:
        parser.error(str(err))
    fresh = [job for job in jobs if peer_record.recorded(record, job) is None]
    if len(fresh) < len(jobs):
        count = len(jobs) - len(fresh)
        print(f"peers: {count} run{'' if count == 1 else 's'} recorded in {path}", flush=True)
    runs, todo = sweep.reuse(fresh, diverged=True)        # a model that failed in training is its cell: not retrained
    sweep.say_reused("peers", runs, todo)
    record = peer_record.record_runs(runs, jobs, settings, path, args.jobs)    # saved by an unrecorded sitting
    # longest first by the recorded runs of each kind, at every seed of the plan
    todo = peer_record.plan_sitting(record, todo, fresh, runs, settings, out, seeds, args.jobs, declared,
                                    not (args.train_only or args.record_only))     # timed; the plan said
    trained, seconds = ({}, {"training": 0.0}) if args.record_only else sweep.train_jobs(
        todo, args.jobs, out / "logs", args.backend, args.ray_address, device=args.device,
        on_done=peer_record.keeper(jobs, settings, path))
    runs.update(trained)
    # a model that failed in training is a result of its config (its table cell says how), not a broken run
    broken = {key: outcome for key, outcome in runs.items() if not (isinstance(outcome, sweep.RunFailed) and outcome.diverged)}
    tic = time.perf_counter()
    record = peer_record.load(path, settings)
    if args.train_only or args.record_only:
        left = sum(peer_record.recorded(record, job) is None for job in jobs)
        print(f"peers: trained {len(todo) if args.train_only else 0}, {len(jobs) - left} of {len(jobs)} runs "
              f"recorded in {path}; no table (--{'train' if args.train_only else 'record'}-only): the same "
              "command without it trains what is left and writes the table", flush=True)
        sweep.exit_if_failed(broken)
        return {"runs": runs, "record": record}
    by_seed = add_seconds(peer_record.by_seed(record, jobs, settings, seeds), jobs, peer_record.walls(record, jobs))
    rows = over_seeds(by_seed) if len(seeds) > 1 else by_seed[args.seed]
    found = peer_record.curves(record, jobs, args.seed)
    if found:
        figure = curves_figure(found, out / "figures" / "peers-curves.png", args.seed)
        if args.update_docs:
            target = hnn.tasks.repo_root() / "docs" / "figures" / "peers-curves.png"
            atomic_write(target, lambda tmp: shutil.copyfile(figure, tmp))
    results = {"meta": {**provenance(), "command": portable_command(argv, "analysis/peers.py"),
                        "quick": not full, "quick_cuts": cuts, "lnn_horizon": settings.get("lnn_horizon"),
                        "reused": len(jobs) - len(todo), "trained": len(todo),
                        "kinds": list(settings["kinds"]), "seeds": list(seeds),
                        "steps": jobs[0].config.total_steps if jobs else None,
                        "optimizer": jobs[0].config.optimizer if jobs else None,
                        "schedule": jobs[0].config.schedule if jobs else None,
                        # measuring: every run's rollouts, whichever sitting recorded it; timing: the kinds' costs here
                        "seconds": {"training": seconds["training"],
                                    "measuring": peer_record.measuring_seconds(record, jobs),
                                    "timing": time.perf_counter() - tic}},
               "rows": rows, "by_seed": by_seed if len(seeds) > 1 else None, "curves": found}
    text = markdown(results)
    seeds = pages.Seeds(len(seeds), None if len(seeds) >= pages.MIN_SEEDS
                                 else f"this run had --seeds {len(seeds)} (the table's default is {FULL_SEEDS})")
    commands.publish(out, "peers", results, text, {"peers": text} if args.update_docs else {}, seeds)
    sweep.exit_if_failed(broken)
    return results
