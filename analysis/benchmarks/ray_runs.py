"""Ray against the local pool, measured (``analysis/benchmarks/ray_overhead.py`` is its command): one
``reproduce.py`` from nothing under a backend, the numbers of two runs compared bit for bit, and Ray's
fixed cost (``ray.init``, a first task, ``ray.shutdown``).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import hnn
from hnn_analysis.provenance import cpu_snapshot, others_load

BACKENDS = ("local", "ray")


def order(repeats: int) -> list[str]:
    """The backends in run order: local, ray, ray, local, local, ray, ... (``repeats`` of each)."""
    return [b for i in range(repeats) for b in (BACKENDS if i % 2 == 0 else BACKENDS[::-1])]


def numbers(tree, prefix: str = "") -> dict[str, float]:
    """The numeric leaves of a ``results.json`` tree by path, without its times (``*seconds*``) and provenance."""
    if isinstance(tree, dict):
        return {k: v for key, sub in tree.items() if key != "meta" and "seconds" not in key
                for k, v in numbers(sub, f"{prefix}/{key}").items()}
    if isinstance(tree, list):
        return {k: v for i, sub in enumerate(tree) for k, v in numbers(sub, f"{prefix}/{i}").items()}
    if isinstance(tree, (int, float)) and not isinstance(tree, bool):
        return {prefix: float(tree)}
    return {}


def compare(a: dict, b: dict) -> dict:
    """How many numbers of two ``results.json`` trees are equal bit for bit, and the worst relative gap."""
    x, y = numbers(a), numbers(b)
    shared = sorted(set(x) & set(y))
    equal = sum(x[k] == y[k] or (x[k] != x[k] and y[k] != y[k]) for k in shared)   # NaN == NaN here
    gaps = {k: abs(x[k] - y[k]) / max(abs(x[k]), abs(y[k])) for k in shared
            if x[k] != y[k] and x[k] == x[k] and y[k] == y[k]}
    return {"numbers": len(shared), "equal": equal, "only_one_side": len(set(x) ^ set(y)),
            "worst_relative_difference": max(gaps.values(), default=0.0),
            "largest_differences": dict(sorted(gaps.items(), key=lambda kv: -kv[1])[:10])}


def run_once(backend: str, full: bool, workdir: Path) -> tuple[dict, dict]:
    """One ``reproduce.py`` from nothing in ``workdir``: its times and its ``results.json``."""
    root = hnn.tasks.repo_root()
    clone, out = workdir / "clone", workdir / "out"
    subprocess.run(["git", "clone", "-q", "--shared", str(root), str(clone)], check=True)
    cmd = [sys.executable, str(root / "analysis" / "reproduce.py"), "--jobs", "2", "--backend", backend,
           "--out", str(out)] + ([] if full else ["--quick"])
    # how busy other processes kept the machine just before: the load average cannot say (a run just
    # ended still weighs on it), the machine's CPU seconds over a second of sleep can
    before = cpu_snapshot()
    time.sleep(1.0)
    others = others_load(before, cpu_snapshot())
    start = time.perf_counter()
    with open(workdir / "log.txt", "w") as log:
        done = subprocess.run(cmd, env={**os.environ, "HNN_REPO": str(clone)}, stdout=log, stderr=subprocess.STDOUT)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed with code {done.returncode}; its log: {workdir / 'log.txt'}")
    results = json.loads((out / "results.json").read_text())
    seconds = results["seconds"]
    return ({"backend": backend, "others_before": others, "wall": wall, "training": seconds["training"],
             "evaluation": seconds["evaluation"]}, results)


def ray_fixed_cost(tries: int = 3) -> list[dict]:
    """Seconds of ``ray.init`` (a local Ray of 2 CPUs), its first task and ``ray.shutdown``, ``tries`` times."""
    import ray
    out = []
    for _ in range(tries):
        t0 = time.perf_counter()
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        t1 = time.perf_counter()
        ray.get(ray.remote(lambda: 1).remote())
        t2 = time.perf_counter()
        ray.shutdown()
        out.append({"init": t1 - t0, "first_task": t2 - t1, "shutdown": time.perf_counter() - t2})
    return out
