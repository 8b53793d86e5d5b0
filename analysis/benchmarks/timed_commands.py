"""The commands ``quick_budgets.py`` times, each from nothing (a fresh clone, a fresh output folder), and the
table it writes: an analysis command's ``--quick``, ``pytest`` and its first check, or the Python of a page."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hnn_analysis import commands
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import cpu_snapshot, machine, others_load

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
        seconds = recorded_seconds(Path(tmp) / "out")     # read before the folder goes
    return {"command": name, "argv": COMMANDS[name], "budget": commands.QUICK_BUDGETS[name], "size": _size(log),
            "wall": wall, "returncode": done.returncode, "others_before": others,
            "load_before": list(load_before), "load_after": list(load_after), "log": str(log), "seconds": seconds}


def recorded_seconds(out: Path) -> dict:
    """``{stage: seconds}`` that a command recorded in the JSON it wrote at the top of ``out`` (its ``"seconds"``,
    or its meta's: reproduce's results.json, the scene study's, peers.json), numbers only; {} where none."""
    found = {}
    for path in sorted(out.glob("*.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):       # not a result of the command's: its seconds are elsewhere or none
            continue
        seconds = data.get("seconds") or data.get("meta", {}).get("seconds") if isinstance(data, dict) else None
        if isinstance(seconds, dict):
            found.update({k: v for k, v in seconds.items() if isinstance(v, (int, float)) and not isinstance(v, bool)})
    return found


def verdict(row: dict) -> str:
    """A timed row in words: within its budget, over by how much, or failed with its exit code."""
    if row["returncode"] != 0:
        return f"FAILED (exit {row['returncode']})"
    return "within" if row["wall"] <= row["budget"] else f"over by {row['wall'] - row['budget']:.0f} s"


def section(result: dict) -> str:
    """The Markdown of docs/speed.md's quick-budgets section: the stamp, one row per command."""
    meta = result["meta"]
    lines = [generated_by(meta, f"{machine(meta)}, torch {meta['torch']}, "
                          f"OMP_NUM_THREADS={result['omp_num_threads'] or 'unset'}") + ": each command from "
             "nothing (a fresh clone, a fresh output folder), one at a time. Load: the 1-minute load average "
             "just before and just after each; others: the cores other processes kept busy in the second "
             "before it started. A box with a load above its 2 cores is not the quiet box the budgets are for.",
             "", "| command | size | budget (s) | wall (s) | verdict | load before | load after | others before |",
             "| --- | --- | ---: | ---: | --- | ---: | ---: | ---: |"]
    for row in result["runs"]:
        shown = f"the Python of {row['argv'][0]}" if row["argv"][0].endswith(".md") else f"python {' '.join(row['argv'])}"
        lines.append(f"| `{shown}` | {row.get('size', '')} | {row['budget']} | {row['wall']:.0f} | {verdict(row)} | "
                     f"{row['load_before'][0]:.2f} | {row['load_after'][0]:.2f} | {row['others_before']:.2f} |")
    busy = [row["command"] for row in result["runs"] if row["others_before"] > 0.5 or row["load_before"][0] > 1.5]
    if busy:
        lines += ["", f"Other work kept this box busy before {', '.join(busy)} (others above 0.5 cores or a load above "
                  "1.5): those times overstate what the command takes on a quiet box, and a verdict there says "
                  "little; rerun on a quiet one."]
    return "\n".join(lines)
