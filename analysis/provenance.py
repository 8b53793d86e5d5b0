"""Where a number came from: the commit, the library versions and the machine, for every JSON a command writes.

    results = {"meta": {**provenance(), "command": ...}, ...}
"""
from __future__ import annotations

import datetime
import os
import platform
import subprocess

import numpy as np
import scipy
import torch

import hnn
from hnn.threads import cores


def commit() -> str:
    """The checkout's short commit hash ('unknown' outside git)."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=hnn.tasks.repo_root(), check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def provenance() -> dict:
    """``{"date", "commit", "torch", "numpy", "scipy", "python", "platform", "machine", "cpu",
    "cores", "threads"}``: what a reader needs to rerun a measurement and compare it."""
    return {"date": datetime.date.today().isoformat(), "commit": commit(), "torch": torch.__version__,
            "numpy": np.__version__, "scipy": scipy.__version__, "python": platform.python_version(),
            "platform": platform.platform(), "machine": platform.machine(),
            "cpu": torch.backends.cpu.get_cpu_capability(), "cores": cores(), "threads": torch.get_num_threads()}


def machine(meta: dict) -> str:
    """The box a timing was taken on, as a stamp names it: ``'2 cores, AVX512'``."""
    return f"{meta.get('cores', '?')} cores, {meta.get('cpu', 'unknown CPU')}"


def cpu_snapshot() -> dict:
    """Wall clock, this process's CPU seconds (with its finished children) and, on Linux, the CPU
    seconds every process on the machine has run since boot; two snapshots give ``others_load``."""
    import resource
    import time
    own = time.process_time() + sum(getattr(resource.getrusage(resource.RUSAGE_CHILDREN), f)
                                    for f in ("ru_utime", "ru_stime"))
    try:
        with open("/proc/stat") as stat:
            machine_busy = busy_seconds(stat.readline(), os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError):
        machine_busy = None
    return {"wall": time.perf_counter(), "own": own, "machine_busy": machine_busy}


def busy_seconds(cpu_line: str, ticks_per_second: int) -> float:
    """The CPU seconds all cores were busy since boot, from /proc/stat's first line (``cpu user nice
    system idle iowait irq softirq steal ...`` in clock ticks): everything but idle and iowait."""
    ticks = [int(v) for v in cpu_line.split()[1:9]]
    return (sum(ticks[:3]) + sum(ticks[5:8])) / ticks_per_second


def others_load(start: dict, end: dict) -> float:
    """Mean number of cores other processes kept busy between two ``cpu_snapshot()`` calls.

    The load average cannot tell: a benchmark's own thread adds 1.0 to it. Off Linux, falls back
    to the one-minute load average at ``end``, which then includes this process."""
    if start["machine_busy"] is None or end["machine_busy"] is None:
        return os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
    wall = max(end["wall"] - start["wall"], 1e-9)
    return max(0.0, (end["machine_busy"] - start["machine_busy"] - (end["own"] - start["own"])) / wall)

