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


def commit() -> str:
    """The checkout's short commit hash ('unknown' outside git)."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=hnn.tasks.repo_root(), check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def cores() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


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
