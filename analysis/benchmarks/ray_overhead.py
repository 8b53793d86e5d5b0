"""What Ray costs against the local pool: the same ``reproduce.py`` under both backends, from nothing.

    python analysis/benchmarks/ray_overhead.py --update-docs                # quick settings, 3 runs of each
    python analysis/benchmarks/ray_overhead.py --full --update-docs         # paper settings (seed 0), 2 of each

Each run is ``python analysis/reproduce.py [--quick] --jobs 2 --backend {local,ray}`` on a fresh
clone of this checkout's commit (``HNN_REPO`` points the tasks there, so every dataset is generated
and every model trained anew), interleaved local, ray, ray, local, ... so that a machine getting
busier or quieter weighs on both. Also times Ray's fixed cost (``ray.init``, a first task,
``ray.shutdown``) and compares the two backends' ``results.json`` number by number. Writes JSON to
``--out`` and, with ``--update-docs``, the section ``ray-quick`` or ``ray-full`` of docs/sweeps.md.
Needs the ray extra: ``pip install -e ".[ray]"``.
"""
from __future__ import annotations

import datetime
import statistics
import sys
import tempfile
from pathlib import Path

import hnn
from hnn.io import write_json
from hnn_analysis import commands, pages
from hnn_analysis.benchmarks.ray_runs import BACKENDS, compare, order, ray_fixed_cost, run_once
from hnn_analysis.provenance import machine, provenance

def _span(values, scale: float = 1.0, digits: int = 1) -> str:
    return f"{scale * min(values):.{digits}f}-{scale * max(values):.{digits}f}"


def section(result: dict) -> str:
    """The Markdown the docs show: stamp, Ray's fixed cost, one row per backend, the comparison."""
    meta, runs, full = result["meta"], result["runs"], result["full"]
    mean = {b: statistics.mean(r["wall"] for r in runs if r["backend"] == b) for b in BACKENDS}
    local = [r["wall"] for r in runs if r["backend"] == "local"]
    fixed = result["ray_fixed_cost"]
    cmp = result["comparison"]
    lines = [pages.generated_by(meta, f"{machine(meta)}, torch {meta['torch']}, Ray {result['ray']}")
             + f": {len(runs) // 2} run(s) of each backend from nothing, "
             f"in the order {', '.join(r['backend'] for r in runs)}; other processes kept "
             f"{_span([r['others_before'] for r in runs], digits=2)} cores busy in the second before each run.", "",
             f"Ray's fixed cost, {len(fixed)} tries: `ray.init` {_span([f['init'] for f in fixed])} s, its first task "
             f"{_span([f['first_task'] for f in fixed], 1e3)} ms, `ray.shutdown` {_span([f['shutdown'] for f in fixed])} s.", "",
             "```bash",
             f"python analysis/reproduce.py{'' if full else ' --quick'} --jobs 2 --out DIR                 # --backend local",
             f"python analysis/reproduce.py{'' if full else ' --quick'} --jobs 2 --backend ray --out DIR",
             "```", "",
             "| backend | training phase (s) | evaluation and figures (s) | command, wall (s) | mean wall (s) |",
             "| --- | --- | --- | --- | ---: |"]
    names = {"local": "local (2 worker processes, 1 thread each)", "ray": "ray (local Ray, 2 CPUs, 1 thread a task)"}
    for b in BACKENDS:
        mine = [r for r in runs if r["backend"] == b]
        cells = [", ".join(f"{r[key]:.1f}" for r in mine) for key in ("training", "evaluation", "wall")]
        lines.append(f"| {names[b]} | {' | '.join(cells)} | {mean[b]:.1f} |")
    diff = mean["ray"] - mean["local"]
    lines += ["", f"Ray against local: {diff:+.1f} s on the mean wall ({100 * diff / mean['local']:+.1f}%); "
              f"the local runs spread over {max(local) - min(local):.1f} s. The first run of each backend gave "
              f"{cmp['equal']} of {cmp['numbers']} numbers in `results.json` bit for bit equal "
              f"(worst relative difference {cmp['worst_relative_difference']:.1e}"
              + (f", in {next(iter(cmp['largest_differences']))}" if cmp["largest_differences"] else "")
              + (f", {cmp['only_one_side']} on one side only" if cmp["only_one_side"] else "") + ")."]
    return "\n".join(lines)


def parse_args(argv=None):
    p = hnn.cli.Parser(description=__doc__.split("\n\n")[0])
    p.add_argument("--full", action="store_true", help="paper settings (seed 0) instead of --quick")
    p.add_argument("--repeats", type=int, default=None, help="runs of each backend (default 3; 2 with --full)")
    p.add_argument("--out", type=Path, default=None,
                   help="where to write the JSON (default results/ray_overhead_{quick,full}.json)")
    p.add_argument("--update-docs", dest="update_docs", action="store_true",
                   help="write the section ray-quick or ray-full of docs/sweeps.md")
    args = p.parse_args(argv)
    args.repeats = args.repeats or (2 if args.full else 3)
    if args.repeats < 1:
        p.error(f"--repeats {args.repeats}: give at least 1")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        import ray
    except ImportError:
        sys.exit('ray_overhead.py compares against Ray, which is not installed: pip install -e ".[ray]"')
    mode = "full" if args.full else "quick"
    out = args.out or hnn.tasks.repo_root() / "results" / f"ray_overhead_{mode}.json"
    meta = {**provenance(), "command": commands.portable_command(sys.argv[1:] if argv is None else list(argv),
                                                       "analysis/benchmarks/ray_overhead.py")}
    meta["date"] = datetime.date.today().isoformat()
    fixed = ray_fixed_cost()
    runs, first = [], {}
    for i, backend in enumerate(order(args.repeats)):
        with tempfile.TemporaryDirectory(prefix=f"ray-overhead-{backend}-") as tmp:
            times, results = run_once(backend, args.full, Path(tmp))
        first.setdefault(backend, results)
        runs.append(times)
        print(f"[{i + 1}/{2 * args.repeats}] {backend}: wall {times['wall']:.1f} s "
              f"(training {times['training']:.1f}, evaluation {times['evaluation']:.1f})", flush=True)
    result = {"meta": meta, "full": args.full, "ray": ray.__version__, "ray_fixed_cost": fixed, "runs": runs,
              "comparison": compare(first["local"], first["ray"])}
    write_json(out, result)
    text = section(result)
    print("\n" + text + f"\n\nwrote {out}")
    if args.update_docs:
        print(f"updated {pages.update_section(f'ray-{mode}', text)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
