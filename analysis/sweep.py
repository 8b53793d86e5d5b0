"""Training sweeps: the runs of a list of jobs trained in this process or in worker processes,
one progress line for the whole sweep.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
from tqdm.auto import tqdm

import hnn

HERE = Path(__file__).resolve().parent


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _train_argv(task: str, label: str, runs_dir: Path, seed: int, steps: int | None, extra_argv=()) -> list[str]:
    """The ``train.py`` flags of one run."""
    argv = ["--save_dir", str(runs_dir), "--seed", str(seed)] + (["--baseline"] if label == "baseline" else [])
    if steps is not None:
        argv += ["--total_steps", str(steps)]
    return argv + list(extra_argv)


def _find(task: str, argv: list[str]) -> Path | None:
    return hnn.find_run(hnn.load_task(task, "train").parse_args(argv))


def _total_steps(task: str, argv: list[str]) -> int:
    """Optimizer steps of a run (the loop runs total_steps + 1)."""
    return hnn.load_task(task, "train").parse_args(argv).total_steps + 1


def train_or_reuse(task: str, label: str, runs_dir: Path, seed: int, steps: int | None = None, extra_argv=(),
                   progress=None) -> tuple[Path, bool]:
    """The run folder of ``task``/``label``, trained now unless a run with identical args exists.

    ``steps`` overrides the task's ``--total_steps``; ``extra_argv`` adds ``train.py`` flags;
    ``progress(step, total)`` is called after every training step. Returns ``(folder, reused)``.
    """
    argv = _train_argv(task, label, runs_dir, seed, steps, extra_argv)
    found = _find(task, argv)
    if found:
        return found, True
    trainer = hnn.load_task(task, "train")
    if progress is None:
        return trainer.main(argv), False
    with hnn.training.report_progress(progress):
        return trainer.main(argv), False


def _fmt_seconds(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class _Progress:
    """One status line for the whole training phase: the runs in progress with their step/total,
    elapsed and estimated remaining time (from the steps done so far, so a rough estimate when
    tasks' steps cost differently). On a terminal a tqdm bar redrawn in place; otherwise a plain
    line at most every ``every`` seconds, so CI logs stay readable.
    """

    def __init__(self, total: int, tty: bool | None = None, every: float = 10.0):
        self.total, self.finished, self.active = max(total, 1), 0, {}
        self.tty = sys.stderr.isatty() if tty is None else tty
        self.every, self.start, self.last = every, time.perf_counter(), -math.inf
        self.bar = (tqdm(total=self.total, unit="step", file=sys.stderr, dynamic_ncols=True, mininterval=0.2,
                         bar_format="{percentage:3.0f}%|{bar:20}| {n_fmt}/{total_fmt} steps "
                                    "[{elapsed}<{remaining}] {desc}") if self.tty else None)

    def update(self, key: str, step: int, total: int) -> None:
        self.active[key] = (step, total)
        self._render()

    def finish(self, key: str, total: int, line: str | None) -> None:
        self.active.pop(key, None)
        self.finished += total
        if line:
            self.write(line)
        self._render(force=True)

    def write(self, line: str) -> None:
        if self.bar is not None:
            self.bar.write(line, file=sys.stdout)
        else:
            print(line, flush=True)

    def _render(self, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last < (0.2 if self.tty else self.every):
            return
        self.last = now
        done = self.finished + sum(step for step, _ in self.active.values())
        runs = ", ".join(f"{key} {step}/{total}" if step else f"{key} starting (data)"
                         for key, (step, total) in self.active.items()) or "-"
        if self.bar is not None:
            self.bar.n = done
            self.bar.set_description_str(runs, refresh=False)
            self.bar.refresh()
            return
        elapsed = now - self.start
        # too few steps for a rate: no estimate yet
        remaining = _fmt_seconds(elapsed * (self.total - done) / done) if done >= 0.02 * self.total else "?"
        print(f"  progress {100 * done / self.total:3.0f}% ({done}/{self.total} steps), elapsed "
              f"{_fmt_seconds(elapsed)}, remaining ~{remaining}: {runs}", flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _run_key(job: dict) -> str:
    return f"{job['row']}/{job['label']}/seed{job['seed']}"


def _summary(job: dict, directory: Path, wall: float) -> str:
    return f"  {job['row']:11s} {job['label']:8s} seed {job['seed']} trained {directory} ({wall:.1f} s)"


# what a run raises when its task cannot run here: missing data or optional packages
_CANNOT_RUN = (FileNotFoundError, ImportError)


def _failed(job: dict, err: Exception, failed_tasks: dict, progress) -> Exception:
    """Record a run that cannot run here; its task's reason is printed once per job, not per run."""
    if job["task"] not in failed_tasks:
        failed_tasks[job["task"]] = err
        progress.write(f"  {job['task']:11s} cannot run here, skipping all its runs: {err}")
    return failed_tasks[job["task"]]


def _train_in_process(jobs: list[dict], progress: _Progress) -> dict:
    """Train ``jobs`` one after another here; ``{key: folder or exception}``."""
    done, failed_tasks = {}, {}
    for job in jobs:
        key, tic = _run_key(job), time.perf_counter()
        if job["task"] in failed_tasks:
            done[key] = failed_tasks[job["task"]]
            progress.finish(key, job["total"], None)
            continue
        progress.update(key, 0, job["total"])
        try:
            directory, _ = train_or_reuse(job["task"], job["label"], job["runs_dir"], job["seed"], job["steps"],
                                          job["extra_argv"], progress=lambda s, t, key=key: progress.update(key, s, t))
        except _CANNOT_RUN as err:
            done[key] = _failed(job, err, failed_tasks, progress)
            progress.finish(key, job["total"], None)
            continue
        job["wall"] = time.perf_counter() - tic
        progress.finish(key, job["total"], _summary(job, directory, job["wall"]))
        done[key] = directory
    return done


def _train_in_workers(jobs: list[dict], n: int, progress: _Progress, log_dir: Path) -> dict:
    """Train ``jobs`` in ``n`` worker processes with ``cores // n`` threads each, longest first
    (the task's ``TaskSpec.cost`` x steps); ``{key: folder or exception}``. A worker's output goes to
    ``<log_dir>/<task>-<label>-seed<seed>.log``; a failure other than missing data raises.
    """
    threads = max(1, _cores() // n)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    # the workers import the same hnn as this process, whatever the install points at
    package_root = str(Path(hnn.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join([package_root] + [p for p in [os.environ.get("PYTHONPATH")] if p])
    queue = sorted(jobs, key=lambda j: hnn.task_spec(j["task"]).cost * j["total"], reverse=True)
    running, done, failed_tasks = {}, {}, {}
    log_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="hnn-progress-") as status_dir:
        try:
            while queue or running:
                for job in [j for j in queue if j["task"] in failed_tasks]:
                    queue.remove(job)
                    done[_run_key(job)] = failed_tasks[job["task"]]
                    progress.finish(_run_key(job), job["total"], None)
                while queue and len(running) < n:
                    # a run whose sibling (same row and seed) is still making their shared dataset
                    # waits, so that dataset is generated once and not twice at the same time
                    ready = [j for j in queue if not any(
                        r["row"] == j["row"] and r["seed"] == j["seed"] and "step" not in _read_status(s)
                        for r, _, s, _, _ in running.values())]
                    if not ready:
                        break
                    job = ready[0]
                    queue.remove(job)
                    key = _run_key(job)
                    status = Path(status_dir) / f"{key.replace('/', '-')}.json"
                    log = open(log_dir / f"{key.replace('/', '-')}.log", "w")
                    argv = _train_argv(job["task"], job["label"], job["runs_dir"], job["seed"], job["steps"],
                                       job["extra_argv"])
                    cmd = [sys.executable, str(HERE / "train_worker.py"), "--threads", str(threads), "--status",
                           str(status), "--task", job["task"], "--"] + argv
                    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
                    running[key] = (job, proc, status, log, time.perf_counter())
                    progress.update(key, 0, job["total"])
                time.sleep(0.3)
                for key, (job, proc, status, log, tic) in list(running.items()):
                    state = _read_status(status)
                    if proc.poll() is None:
                        if "step" in state:
                            progress.update(key, state["step"], state["total"])
                        continue
                    log.close()
                    del running[key]
                    job["wall"] = time.perf_counter() - tic
                    if proc.returncode == 0 and state.get("done"):
                        done[key] = Path(state["run"])
                        progress.finish(key, job["total"], _summary(job, done[key], job["wall"]))
                    elif state.get("type") in ("FileNotFoundError", "ImportError", "ModuleNotFoundError"):
                        err = (ImportError if "Import" in state["type"] or "Module" in state["type"]
                               else FileNotFoundError)(state["error"])
                        done[key] = _failed(job, err, failed_tasks, progress)
                        progress.finish(key, job["total"], None)
                    else:
                        tail = "".join(Path(log.name).read_text().splitlines(keepends=True)[-15:])
                        raise RuntimeError(f"training {key} failed (exit {proc.returncode}); the end of {log.name}:\n{tail}")
        finally:
            for _job, proc, _status, log, _tic in running.values():
                proc.kill()
                proc.wait()
                log.close()
    return done


def _read_status(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _metrics(directory: Path) -> dict:
    try:
        return json.loads((Path(directory) / "metrics.json").read_text())
    except (OSError, ValueError):
        return {}


def train_jobs(jobs: list[dict], n_jobs: int, log_dir: Path) -> tuple[dict, dict]:
    """Train ``jobs`` (here, or in ``n_jobs`` workers); ``({key: folder or exception}, seconds)``."""
    tic, runs = time.perf_counter(), {}
    if jobs:
        progress = _Progress(sum(job["total"] for job in jobs))
        try:
            if n_jobs == 1:
                runs = _train_in_process(jobs, progress)
            else:
                runs = _train_in_workers(jobs, n_jobs, progress, log_dir)
        finally:
            progress.close()
    seconds = {"training": time.perf_counter() - tic, "jobs": n_jobs,
               "threads_per_job": max(1, _cores() // n_jobs) if n_jobs > 1 else torch.get_num_threads(), "runs": {}}
    for job in jobs:
        key = _run_key(job)
        if isinstance(runs.get(key), Path):
            m = _metrics(runs[key])
            seconds["runs"][key] = {"data": m.get("data_seconds"), "train": m.get("train_seconds"),
                                    "wall": job.get("wall")}
    return runs, seconds

