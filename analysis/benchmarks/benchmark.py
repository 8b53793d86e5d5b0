"""Time our implementation against the same work done the way the original code did it.

    python analysis/benchmarks/benchmark.py                 # 5 interleaved rounds of every job
    python analysis/benchmarks/benchmark.py --quick         # 1 round, fewer training steps and trials
    python analysis/benchmarks/benchmark.py --jobs train,eval --repeats 3 --out results/bench.json
    python analysis/benchmarks/benchmark.py --jobs floor    # only the training steps against their floor
    python analysis/benchmarks/benchmark.py --jobs rollout  # only rollouts of learned models against their floor
    python analysis/benchmarks/benchmark.py --jobs group    # only grouped training against separate runs
    python analysis/benchmarks/benchmark.py --jobs group --update-docs   # rewrite only the group table and its stamp

What each job times and how: ``benchmark_jobs``'s docstring; the report: ``benchmark_report``.
"""
from __future__ import annotations

import datetime
import sys

import hnn

from hnn.io import write_json
from hnn_analysis import commands, pages
from hnn_analysis.benchmarks import benchmark_jobs, floor_job
from hnn_analysis.benchmarks.benchmark_jobs import JOBS
from hnn_analysis.benchmarks.benchmark_report import benchmark_section, ceiling, jobs_table


def parse_args(argv=None):
    parser = hnn.cli.Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=None, help="interleaved rounds per job (default 5; 1 with --quick)")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads for the data, train and eval comparisons (default 1: one thread each, "
                             "as the original's train.py is timed); the floor job always runs 1, then 2")
    parser.add_argument("--floor-rounds", type=int, default=None,
                        help="step/floor rounds of the spring step (default 200; 40 with --quick); the pixel step runs a quarter")
    parser.add_argument("--quick", action="store_true", help="1 round, 200 training steps, 5 evaluation trials")
    parser.add_argument("--out", default="results/benchmark.json", help="where to write the JSON results")
    parser.add_argument("--jobs", default=",".join(JOBS), help="comma list of " + ",".join(JOBS))
    parser.add_argument("--update-docs", dest="update_docs", action="store_true",
                        help="write the generated section of docs/speed.md")
    args = parser.parse_args(argv)
    args.jobs = [j.strip() for j in args.jobs.split(",") if j.strip()]
    bad = [j for j in args.jobs if j not in JOBS]
    if bad or not args.jobs:
        parser.error(f"--jobs must be a comma list of {','.join(JOBS)}; got {bad or 'nothing'}")
    if args.repeats is None:
        args.repeats = 1 if args.quick else 5
    if args.floor_rounds is None:
        args.floor_rounds = 40 if args.quick else 200
    if args.repeats < 1 or args.floor_rounds < 1 or args.threads < 1:
        parser.error(f"--repeats, --floor-rounds and --threads must be at least 1; got {args.repeats}, "
                     f"{args.floor_rounds} and {args.threads}")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    run = benchmark_jobs.run_jobs(args)
    steps, protocol, env, results = run["steps"], run["protocol"], run["env"], run["results"]
    floors, rollouts, group = run["floors"], run["rollouts"], run["group"]
    checked = {**({"floor": floors} if floors else {}), **results}
    failed = [f"{job}: {c['name']}" for job, r in checked.items() for c in r["checks"] if not c["passed"]]
    floor_table = floor_job.floor_table(floors) if floors else ""
    if floors:
        floor_table += "\n\n" + "\n".join(
            f"Check: {c['name']} = {c['value']:.3g} (tolerance {c['tolerance']:g}): {'pass' if c['passed'] else 'FAIL'}."
            for c in floors["checks"])
    table = "\n\n".join(t for t in (jobs_table(results, steps, protocol.num_trials) if results else "",
                                     ceiling(results, floors, steps)) if t)
    print()
    rollout_table = rollouts["table"] if rollouts else ""
    group_table = group["table"] if group else ""
    print("\n\n".join(t for t in (floor_table, table, rollout_table, group_table) if t))
    for job, r in checked.items():
        for c in r["checks"]:
            extra = {k: v for k, v in c.items() if k not in ("name", "value", "tolerance", "passed")}
            print(f"check {job}: {c['name']} = {c['value']:.3e} (tolerance {c['tolerance']:g}) "
                  f"{'pass' if c['passed'] else 'FAIL'} {extra}")
    write_json(args.out, {"environment": env, "repeats": args.repeats, "quick": args.quick,
                          "total_steps": steps, "jobs": results, "table": table, "floor": floors,
                          "floor_table": floor_table, "rollouts": rollouts, "group": group,
                          "all_checks_passed": not failed})
    print(f"\nwrote {args.out}")
    if args.update_docs:
        command = commands.portable_command(sys.argv[1:] if argv is None else list(argv), "analysis/benchmarks/benchmark.py")
        busy = env["others_load"]
        shared = (f" **The machine was shared while measuring** (other processes kept {busy:.1f} of "
                  f"{env['cores']} cores busy on average): they slowed both sides of every ratio, unevenly."
                  if busy > 0.3 else "")
        machine = f"torch {env['torch']}, {env['cores']} cores{', ' + env['cpu'] if env['cpu'] else ''}"
        meta = {"command": command, "date": datetime.date.today().isoformat(), "commit": env["commit"]}
        stamp = pages.generated_by(meta, machine)
        head = (pages.generated_by(meta, f"{machine}, {env['torch_threads']} threads for the comparisons, "
                                         f"{args.repeats} interleaved rounds") + f".{shared}")
        body = "\n\n".join(t for t in (floor_table, table, rollout_table) if t)
        pages.update_section("benchmark", benchmark_section(head + "\n\n" + body if body else None,
                                                              f"{stamp}.{shared}\n\n{group_table}" if group else None))
        print("updated docs/speed.md")
    if failed:
        print("FAILED checks: " + "; ".join(failed), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
