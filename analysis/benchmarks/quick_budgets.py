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
quiet one. ``--out`` gets ``quick_budgets.json`` and each command's log.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import hnn
from hnn.io import write_json
from hnn_analysis import commands, pages
from hnn_analysis.provenance import cpu_snapshot, machine, others_load, provenance

# the shipped two-mass measurements of docs/measured.md: the --data study's smoke run
MEASURED = ["--data", "experiment-measured/systems/real_double_linear_h_1.txt", "--time", "t", "--q", "x1,x2",
            "--v", "v1,v2", "--trial", "trial"]
# name (a key of commands.QUICK_BUDGETS) -> the command's script and its arguments, before --out
COMMANDS = {"reproduce": ["analysis/reproduce.py", "--quick"],
            "scene_study": ["analysis/scene_study.py", "--quick"],
            "scene_study --data": ["analysis/scene_study.py", *MEASURED, "--quick"],
            "peers": ["analysis/peers.py", "--quick"],
            "dgnet": ["analysis/chains/dgnet.py", "--quick"],
            "pytest": ["-m", "pytest", "-q", "-p", "no:cacheprovider"],
            "pytest -m quick": ["-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "quick"],
            "README's Python": ["README.md", r"## Use it from Python\s*```python\n(.*?)```"],
            "docs/python.md's Duffing": ["docs/python.md", r"<!-- example: custom-system -->\s*```python\n(.*?)```"]}
# what a command's log says of its size: its tests, the rows of its file, the runs it trains
SIZES = ((r"(\d+) passed", "{} tests"), (r"\((\d+) rows\)", "{} rows"), (r"  train (\d+) runs?:", "{} runs trained"))


def _clone(root: Path, where: Path) -> Path:
    """A fresh copy of the checkout's commit at ``where`` (no dataset cached, no run saved)."""
    done = subprocess.run(["git", "clone", "-q", "--shared", str(root), str(where)], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"git clone of {root} failed ({done.stderr.strip()}); the benchmark needs a git checkout")
    return where


def _command(name: str, root: Path, clone: Path, tmp: str) -> list[str]:
    """The argv of ``name``: a script with its words and ``--out``, pytest in the clone, or the Python block of a
    page (its pattern's first group) written to a file and run as written."""
    script, *words = COMMANDS[name]
    if script == "-m":
        return [sys.executable, script, *words]
    if script.endswith(".md"):
        code = re.search(words[0], (clone / script).read_text(), re.S).group(1)
        path = Path(tmp) / f"{Path(script).stem}.py"
        path.write_text(code)
        return [sys.executable, str(path)]
    # paths into the checkout (a data file) are read from the clone, as a reader's own would be
    words = [str(clone / w) if (root / w).is_file() else w for w in words]
    return [sys.executable, str(root / script), *words, "--out", str(Path(tmp) / "out")]


def _size(log: Path) -> str:
    """The size of what a command did, as its log says it (``SIZES``), or ''."""
    text = log.read_text(errors="replace")
    return ", ".join(words.format(found[-1]) for pattern, words in SIZES if (found := re.findall(pattern, text)))


def run_one(name: str, root: Path, log_dir: Path) -> dict:
    """``name``'s quick command from nothing: wall seconds, exit code, the loads around it and its log."""
    log = log_dir / f"{re.sub(r'[^A-Za-z0-9_.-]', '', name.replace(' ', '-'))}.log"
    with tempfile.TemporaryDirectory(prefix="quick-budget-") as tmp:
        clone = _clone(root, Path(tmp) / "clone")
        cmd = _command(name, root, clone, tmp)
        before = cpu_snapshot()
        time.sleep(1.0)
        others = others_load(before, cpu_snapshot())
        load_before = os.getloadavg()
        start = time.perf_counter()
        with open(log, "w") as out:
            done = subprocess.run(cmd, env={**os.environ, "HNN_REPO": str(clone)}, stdout=out,
                                  stderr=subprocess.STDOUT, cwd=clone if COMMANDS[name][0] == "-m" else tmp)
        wall = time.perf_counter() - start
        load_after = os.getloadavg()
    return {"command": name, "argv": COMMANDS[name], "budget": commands.QUICK_BUDGETS[name], "size": _size(log),
            "wall": wall, "returncode": done.returncode, "others_before": others,
            "load_before": list(load_before), "load_after": list(load_after), "log": str(log)}


def _verdict(row: dict) -> str:
    if row["returncode"] != 0:
        return f"FAILED (exit {row['returncode']})"
    return "within" if row["wall"] <= row["budget"] else f"over by {row['wall'] - row['budget']:.0f} s"


def section(result: dict) -> str:
    """The Markdown of docs/speed.md's quick-budgets section: the stamp, one row per command."""
    meta = result["meta"]
    lines = [f"`{meta['command']}` on {meta['date']} (commit {meta['commit']}, {machine(meta)}, torch "
             f"{meta['torch']}, OMP_NUM_THREADS={result['omp_num_threads'] or 'unset'}): each command from "
             "nothing (a fresh clone, a fresh output folder), one at a time. Load: the 1-minute load average "
             "just before and just after each; others: the cores other processes kept busy in the second "
             "before it started. A box with a load above its 2 cores is not the quiet box the budgets are for.",
             "", "| command | size | budget (s) | wall (s) | verdict | load before | load after | others before |",
             "| --- | --- | ---: | ---: | --- | ---: | ---: | ---: |"]
    for row in result["runs"]:
        shown = f"the Python of {row['argv'][0]}" if row["argv"][0].endswith(".md") else f"python {' '.join(row['argv'])}"
        lines.append(f"| `{shown}` | {row.get('size', '')} | {row['budget']} | {row['wall']:.0f} | {_verdict(row)} | "
                     f"{row['load_before'][0]:.2f} | {row['load_after'][0]:.2f} | {row['others_before']:.2f} |")
    busy = [row["command"] for row in result["runs"] if row["others_before"] > 0.5 or row["load_before"][0] > 1.5]
    if busy:
        lines += ["", f"Other work kept this box busy before {', '.join(busy)} (others above 0.5 cores or a load above "
                  "1.5): those times overstate what the command takes on a quiet box, and a verdict there says "
                  "little; rerun on a quiet one."]
    return "\n".join(lines)


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
    runs, tic = [], time.perf_counter()
    for i, name in enumerate(names, 1):
        print(f"[{i}/{len(names)}, {time.perf_counter() - tic:.0f} s] {name}: python {' '.join(COMMANDS[name])} "
              "(from nothing) ...", flush=True)
        row = run_one(name, root, out)
        runs.append(row)
        print(f"  {row['wall']:.1f} s against a budget of {row['budget']} s: {_verdict(row)}; load "
              f"{row['load_before'][0]:.2f} before, {row['load_after'][0]:.2f} after; log {row['log']}", flush=True)
    result = {"meta": meta, "omp_num_threads": os.environ.get("OMP_NUM_THREADS"), "runs": runs}
    write_json(out / "quick_budgets.json", result)
    text = section(result)
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
