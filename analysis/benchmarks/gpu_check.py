"""The checks a GPU session runs, as one command: the cuda tests, the many-models benchmark, and the
reproduction's seeds against their time target; each step's output and time into ``gpu_check.json``.

    python analysis/benchmarks/gpu_check.py --out results-gpu            # on a machine with a GPU
    python analysis/benchmarks/gpu_check.py --steps tests,bench          # some of the steps
    python analysis/benchmarks/gpu_check.py --update-docs                # docs/gpu.md's sections

Steps (each a subprocess of this interpreter, stopped at its time limit, the next one runs anyway):

- ``tests``: ``pytest -m cuda tests/test_devices.py tests/test_stacked.py`` (every task and kind, every
  solver and a group on cuda, beside the CPU suite's checks of the same);
- ``bench``: ``analysis/benchmarks/benchmark_many.py --devices cuda`` (K = 1 .. 1024 spring HNNs);
- ``reproduce``: ``analysis/reproduce.py --seeds 15 --device cuda --no-figures`` (target: 300 s; the
  pixel task needs gymnasium and is left out where it is missing).
"""
from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from pathlib import Path

import torch

import hnn

from hnn_analysis import commands
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import provenance

STEPS = ("tests", "bench", "reproduce")
TARGETS = {"reproduce": 300.0}        # seconds (#44)
LIMITS = {"tests": 600, "bench": 600, "reproduce": 900}


def _command(step: str, out: Path) -> list[str]:
    if step == "tests":
        return [sys.executable, "-m", "pytest", "-q", "-m", "cuda", "tests/test_devices.py", "tests/test_stacked.py"]
    if step == "bench":
        return [sys.executable, "analysis/benchmarks/benchmark_many.py", "--devices", "cuda", "--out", str(out / "bench")]
    tasks = ["spring", "pend", "real", "2body", "3body"]
    if importlib.util.find_spec("gymnasium") is not None:
        tasks.append("pixels")
    return [sys.executable, "analysis/reproduce.py", "--seeds", "15", "--device", "cuda", "--no-figures",
            "--tasks", *tasks, "--out", str(out / "reproduce")]


def run_step(step: str, out: Path) -> dict:
    """One step as a subprocess: its command, exit code, seconds and the last lines it printed."""
    command = _command(step, out)
    tic = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=LIMITS[step])
        code, text = done.returncode, done.stdout + done.stderr
    except subprocess.TimeoutExpired as err:          # what it printed before its limit
        printed = err.stdout.decode(errors="replace") if isinstance(err.stdout, bytes) else (err.stdout or "")
        code, text = "timeout", printed
    seconds = time.perf_counter() - tic
    tail = "\n".join(text.strip().splitlines()[-15:])
    print(f"{step}: exit {code} in {seconds:.0f} s\n{tail}\n", flush=True)
    return {"command": " ".join(Path(c).name if c == sys.executable else c for c in command), "exit": code,
            "seconds": seconds, "target": TARGETS.get(step), "tail": tail}


def table(results: dict) -> str:
    meta = results["meta"]
    lines = [generated_by(meta, f"{meta.get('gpu') or 'no GPU'}, torch {meta['torch']}") + ":", "", "| step | command | exit | seconds | target |", "| --- | --- | --- | ---: | ---: |"]
    for step, r in results["steps"].items():
        target = f"{r['target']:.0f}" if r["target"] else ""
        lines.append(f"| {step} | `{r['command']}` | {r['exit']} | {r['seconds']:.0f} | {target} |")
    return "\n".join(lines)


def main(argv=None) -> dict:
    parser = hnn.cli.Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", default=",".join(STEPS), help="comma list of " + ",".join(STEPS))
    commands.add_flags(parser, out="folder for gpu_check.json and each step's output", out_default=Path("results-gpu"),
                       update_docs="write the steps' table into docs/gpu.md")
    args = parser.parse_args(argv)
    steps = [s.strip() for s in args.steps.split(",") if s.strip()]
    if not steps or any(s not in STEPS for s in steps):
        parser.error(f"--steps must be a comma list of {','.join(STEPS)}; got {args.steps!r}")
    if not torch.cuda.is_available():
        sys.exit("error: torch sees no CUDA device here; run this on a machine with a GPU")
    meta = {**provenance(), "gpu": torch.cuda.get_device_name(0),
            "command": commands.portable_command(sys.argv[1:] if argv is None else list(argv),
                                                 "analysis/benchmarks/gpu_check.py")}
    results = {"meta": meta, "steps": {step: run_step(step, args.out) for step in steps}}
    text = table(results)
    commands.publish(args.out, "gpu_check", results, text + "\n", {"gpu-check": text} if args.update_docs else {})
    return results


if __name__ == "__main__":
    main()
