"""Reproduce the paper's three tables (train loss, test loss, energy MSE; baseline vs HNN) and
its figures, for every task in this checkout.

    python analysis/reproduce.py                      # full settings, results/
    python analysis/reproduce.py --quick              # smoke run (300 steps), results-quick/
    python analysis/reproduce.py --jobs 2             # two training processes, one thread each
    python analysis/reproduce.py --tasks spring --update-readme

Trains each model through its task's own ``train.py`` (reusing a saved run only when its args
match exactly), in this process or in ``--jobs N`` worker processes (longest runs first), with
one progress line for the whole job; then evaluates the energy MSE under the paper's protocol
and a corrected one and draws the figures (per task, through ``task_hooks.HOOKS``). Writes
``<out>/results.json`` (every number, with versions, commit, seed and the time of each stage),
``<out>/tables.md`` (built from that JSON: ours beside the paper's, marked, and the stage
times) and ``<out>/figures/``.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy
import torch
from tqdm.auto import tqdm

import hnn
from hnn.runs import atomic_write, write_json
import readme
import task_hooks
from paper_numbers import PAPER

MODELS = ("baseline", "hnn")
METRICS = (("train_loss", "Train loss"), ("test_loss", "Test loss"))
QUICK_STEPS = 300
MARKS = {"within": "✓", "better": "↓", "worse": "↑"}
LEGEND = ("Marks: ✓ within the paper's ± (|ours − paper| ≤ the paper's ±); ↓ lower than the paper beyond "
          "its ± (better); ↑ higher than the paper beyond its ± (worse).")
HERE = Path(__file__).resolve().parent


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=hnn.tasks.repo_root(), check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


# ----------------------------------------------------------------------------------------------
# training


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

    def finish(self, key: str, total: int, line: str) -> None:
        self.active.pop(key, None)
        self.finished += total
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
    return f"{job['task']}/{job['label']}/seed{job['seed']}"


def _summary(job: dict, directory: Path, wall: float) -> str:
    return f"  {job['task']:7s} {job['label']:8s} seed {job['seed']} trained {directory} ({wall:.1f} s)"


def _train_in_process(jobs: list[dict], progress: _Progress) -> dict:
    """Train ``jobs`` one after another here; ``{key: folder or exception}``."""
    done = {}
    for job in jobs:
        key, tic = _run_key(job), time.perf_counter()
        progress.update(key, 0, job["total"])
        try:
            directory, _ = train_or_reuse(job["task"], job["label"], job["runs_dir"], job["seed"], job["steps"],
                                          job["extra_argv"], progress=lambda s, t, key=key: progress.update(key, s, t))
        except (FileNotFoundError, ImportError) as err:   # missing data or optional packages; reported by the caller
            progress.finish(key, job["total"], f"  {job['task']:7s} {job['label']:8s} seed {job['seed']} failed: {err}")
            done[key] = err
            continue
        job["wall"] = time.perf_counter() - tic
        progress.finish(key, job["total"], _summary(job, directory, job["wall"]))
        done[key] = directory
    return done


def _train_in_workers(jobs: list[dict], n: int, progress: _Progress, log_dir: Path) -> dict:
    """Train ``jobs`` in ``n`` worker processes with ``cores // n`` threads each, longest first
    (``task_hooks`` cost x steps); ``{key: folder or exception}``. A worker's output goes to
    ``<log_dir>/<task>-<label>-seed<seed>.log``; a failure other than missing data raises.
    """
    threads = max(1, _cores() // n)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    # the workers import the same hnn as this process, whatever the install points at
    package_root = str(Path(hnn.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join([package_root] + [p for p in [os.environ.get("PYTHONPATH")] if p])
    queue = sorted(jobs, key=lambda j: task_hooks.hooks_for(j["task"]).cost * j["total"], reverse=True)
    running, done = {}, {}
    log_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="hnn-progress-") as status_dir:
        try:
            while queue or running:
                while queue and len(running) < n:
                    # a run whose sibling (same task and seed) is still making their shared dataset
                    # waits, so that dataset is generated once and not twice at the same time
                    ready = [j for j in queue if not any(
                        r["task"] == j["task"] and r["seed"] == j["seed"] and "step" not in _read_status(s)
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
                        done[key] = (ImportError if "Import" in state["type"] or "Module" in state["type"]
                                     else FileNotFoundError)(state["error"])
                        progress.finish(key, job["total"], f"  {job['task']:7s} {job['label']:8s} seed "
                                                           f"{job['seed']} failed: {state['error']}")
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


# ----------------------------------------------------------------------------------------------
# evaluation


def evaluate_task(task: str, runs: dict, fig_dir: Path | None) -> dict:
    """Losses from the saved metrics, energy MSE under every protocol, and the figures (through
    the task's ``task_hooks`` entry). ``runs`` is ``{label: run folder}``; the row's
    ``"seconds"`` holds the time of the evaluation and of the figures.
    """
    hooks = task_hooks.hooks_for(task)
    system = hnn.load_task(task)
    tic = time.perf_counter()
    models, row = {}, {label: {} for label in runs}
    for label, directory in runs.items():
        models[label], args, metrics = hooks.load(directory)
        row[label]["train_loss"] = [metrics["train_loss"], metrics["train_loss_se"]]
        row[label]["test_loss"] = [metrics["test_loss"], metrics["test_loss_se"]]
        row[label]["train_seconds"] = metrics.get("train_seconds")
        row[label]["data_seconds"] = metrics.get("data_seconds")
        row[label]["total_steps"] = args["total_steps"]
    energy = hooks.evaluate(task, system, models)
    for name, result in energy.items():
        for label in models:
            row[label][f"energy_mse_{name}"] = [result[label]["mse"], result[label]["mse_se"]]
        row.setdefault("protocols", {})[name] = result.get("description", name)
    t_eval = time.perf_counter() - tic
    if fig_dir is not None:
        numbers = hooks.figures(task, system, models, energy, Path(fig_dir))
        if numbers:
            row["figure_numbers"] = numbers
    row["seconds"] = {"evaluate": t_eval, "figures": time.perf_counter() - tic - t_eval if fig_dir else 0.0}
    return row


# ----------------------------------------------------------------------------------------------
# tables


def _fmt(pair) -> str:
    return "n/a" if pair is None else f"{pair[0]:.4e} ± {pair[1]:.2e}"


def _ratio(ours, paper) -> str:
    return "" if ours is None or paper is None else f"{ours[0] / paper[0]:.2f}x"


def compare(ours, paper) -> str | None:
    """``'within'`` when |ours - paper| <= the paper's ± (equality up to rounding counts as
    within), else ``'better'`` (lower) or ``'worse'`` (higher); None when either is missing.
    ``ours`` and ``paper`` are ``(mean, ±)`` pairs.
    """
    if ours is None or paper is None:
        return None
    gap, band = abs(ours[0] - paper[0]), abs(paper[1])
    if gap <= band or math.isclose(gap, band, rel_tol=1e-9):
        return "within"
    return "better" if ours[0] < paper[0] else "worse"


def _marked(ours, paper) -> str:
    verdict = compare(ours, paper)
    return _fmt(ours) + (f" {MARKS[verdict]}" if verdict else "")


def _across_seeds(row: dict, label: str, key: str) -> str:
    """Mean ± standard error over seeds of one metric, or '' for a single seed."""
    values = [r[label][key][0] for r in row.get("per_seed", {}).values() if r[label].get(key)]
    if len(values) < 2:
        return ""
    return f"{np.mean(values):.4e} ± {np.std(values, ddof=1) / np.sqrt(len(values)):.2e} (n={len(values)})"


def _s(value) -> str:
    return "" if value is None else f"{value:.1f}"


def stage_table(results: dict) -> list[str]:
    """Markdown lines: the seconds of each stage per task, and the wall times."""
    seconds = results.get("seconds", {})
    if not seconds.get("tasks"):
        return []
    jobs = seconds.get("jobs", 1)
    lines = ["**Time per stage** (seconds in this invocation; data = dataset load or generation inside "
             "train.py, train = the training loop, summed over seeds; reused = a saved run with the same args)", "",
             "| task | data | train baseline | train hnn | evaluate | figures |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for task, s in seconds["tasks"].items():
        train = [_s(s["train"].get(label)) if label in s["train"] else "reused" for label in MODELS]
        lines.append(f"| {task} | {_s(s.get('data')) if s.get('data') is not None else 'reused'} | "
                     f"{train[0]} | {train[1]} | {_s(s.get('evaluate'))} | {_s(s.get('figures'))} |")
    overlap = f"{jobs} worker processes of {seconds.get('threads_per_job')} threads, so runs overlap" if jobs > 1 \
        else "in this process"
    lines += ["", f"Wall time: training {_s(seconds.get('training'))} s ({overlap}), evaluation and figures "
                  f"{_s(seconds.get('evaluation'))} s, total {_s(seconds.get('total'))} s."]
    return lines


def tables_markdown(results: dict) -> str:
    """The three tables, ours beside the paper's, and the stage times, from a results dict (``results.json``)."""
    meta = results["meta"]
    lines = []
    if meta.get("quick"):
        lines += [f"**QUICK smoke run ({meta.get('steps')} steps per model): not the paper's settings, so the "
                  "numbers are not comparable with the paper's.**", ""]
    lines += [f"Generated by `{meta['command']}` on {meta['date']} (commit {meta['commit']}, seed {meta['seed']}, "
              f"torch {meta['torch']}, {meta['mode']}). Ratio = ours / paper. {LEGEND}", ""]
    seeds = f"seeds {meta['seeds']}: mean ± standard error of the seeds' means" if len(meta["seeds"]) > 1 else ""
    for key, title in METRICS:
        lines += [f"**{title}** (mean ± std/sqrt(rows), seed {meta['seed']})", "",
                  f"| task | model | paper | ours | ratio |{' across ' + seeds + ' |' if seeds else ''}",
                  f"| --- | --- | --- | --- | --- |{' --- |' if seeds else ''}"]
        for task, row in results["tasks"].items():
            for label in MODELS:
                paper, ours = PAPER.get(task, {}).get(key, {}).get(label), row[label].get(key)
                extra = f" {_across_seeds(row, label, key)} |" if seeds else ""
                lines.append(f"| {task} | {label} | {_fmt(paper)} | {_marked(ours, paper)} | "
                             f"{_ratio(ours, paper)} |{extra}")
        lines.append("")
    lines += [f"**Energy MSE** (mean ± batch-means standard error over 5 groups, seed {meta['seed']})", "",
              "| task | model | paper | ours, paper protocol | ratio | ours, corrected protocol |"
              + (f" paper protocol across {seeds} |" if seeds else ""),
              "| --- | --- | --- | --- | --- | --- |" + (" --- |" if seeds else "")]
    for task, row in results["tasks"].items():
        for label in MODELS:
            paper = PAPER.get(task, {}).get("energy_mse", {}).get(label)
            ours, fixed = row[label].get("energy_mse_paper"), row[label].get("energy_mse_corrected")
            extra = f" {_across_seeds(row, label, 'energy_mse_paper')} |" if seeds else ""
            lines.append(f"| {task} | {label} | {_fmt(paper)} | {_marked(ours, paper)} | {_ratio(ours, paper)} | "
                         f"{_fmt(fixed) if fixed else 'same as paper'} |{extra}")
    lines += ["", "Protocols:"]
    for task, row in results["tasks"].items():
        for text in row.get("protocols", {}).values():
            lines.append(f"- {task}, {text}")
    skipped = results.get("skipped", {})
    for task in skipped:
        lines += ["", f"Skipped {task}: {skipped[task]}"]
    present = meta.get("available", hnn.available_tasks())
    missing = [t for t in hnn.tasks.TASKS if t not in present]
    if missing:
        lines += ["", f"Not yet in this checkout: {', '.join(missing)}."]
    stages = stage_table(results)
    if stages:
        lines += [""] + stages
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------
# the command


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=None, help="tasks to run (default: every task present)")
    p.add_argument("--quick", action="store_true",
                   help=f"smoke run: {QUICK_STEPS} training steps per model (or --steps), output in results-quick/")
    p.add_argument("--steps", type=int, default=None,
                   help="training steps per model, overriding every task's default (with --quick: default "
                        f"{QUICK_STEPS}); a run trained with other steps is retrained")
    p.add_argument("--out", type=Path, default=None, help="output folder (default results/ or results-quick/)")
    p.add_argument("--seed", type=int, default=0, help="seed of the datasets, inits and minibatches")
    p.add_argument("--seeds", type=int, default=1,
                   help="train and evaluate seeds seed .. seed+N-1; tables add mean ± standard error across them")
    p.add_argument("--jobs", type=int, default=1,
                   help="training processes: 1 trains here, one run after another; N > 1 runs N worker "
                        "processes with cores // N threads each, longest runs first; evaluation stays here")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--update-readme", action="store_true", help="paste tables.md into README.md's results section")
    return p


def _check(args) -> None:
    if args.jobs < 1:
        raise SystemExit(f"--jobs must be at least 1 (1 = train in this process), got {args.jobs}")
    if args.seeds < 1:
        raise SystemExit(f"--seeds must be at least 1, got {args.seeds}")
    if args.steps is not None and args.steps < 0:
        raise SystemExit(f"--steps must be a non-negative number of training steps, got {args.steps}")
    if args.update_readme and (args.quick or args.steps is not None):
        raise SystemExit("--update-readme pastes full-settings results into README.md; drop --quick / --steps")
    for task in args.tasks or []:
        if task not in hnn.available_tasks():
            raise SystemExit(f"unknown or missing task {task!r}; available: {hnn.available_tasks()}")


def _metrics(directory: Path) -> dict:
    try:
        return json.loads((Path(directory) / "metrics.json").read_text())
    except (OSError, ValueError):
        return {}


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = _parser().parse_args(argv)
    _check(args)
    root = hnn.tasks.repo_root()
    out = args.out or root / ("results-quick" if args.quick else "results")
    tasks = args.tasks or hnn.available_tasks()
    steps = args.steps if args.steps is not None else (QUICK_STEPS if args.quick else None)
    if args.quick:
        mode = f"QUICK smoke run, {steps} steps per model: not the paper's settings"
    else:
        mode = "full settings" if steps is None else f"{steps} steps per model: not the paper's settings"
    print(f"reproduce: tasks {', '.join(tasks)}; {mode}; --jobs {args.jobs}; output {out}", flush=True)
    seeds = list(range(args.seed, args.seed + args.seeds))
    results = {"meta": {"command": " ".join(["python analysis/reproduce.py"] + argv),
                        "date": datetime.date.today().isoformat(), "commit": _commit(), "seed": args.seed,
                        "seeds": seeds, "mode": mode, "quick": args.quick, "steps": steps, "jobs": args.jobs,
                        "torch": torch.__version__, "numpy": np.__version__, "scipy": scipy.__version__,
                        "python": platform.python_version(), "threads": torch.get_num_threads(), "cores": _cores(),
                        "available": hnn.available_tasks()},
               "tasks": {}, "seconds": {"tasks": {}, "runs": {}}}
    start = time.perf_counter()

    # 1. which runs exist already (same args), which must be trained
    runs, jobs = {}, []
    for task in tasks:
        hooks = task_hooks.hooks_for(task)
        extra = hooks.train_argv + (hooks.quick_argv if args.quick else ())
        for seed in seeds:
            for label in MODELS:
                job = {"task": task, "label": label, "seed": seed, "runs_dir": out / "runs", "steps": steps,
                       "extra_argv": list(extra)}
                argv_run = _train_argv(task, label, out / "runs", seed, steps, extra)
                found = _find(task, argv_run)
                if found:
                    runs[_run_key(job)] = found
                    print(f"  {task:7s} {label:8s} seed {seed} reused {found}", flush=True)
                else:
                    jobs.append(dict(job, total=_total_steps(task, argv_run)))

    # 2. train what is missing
    tic = time.perf_counter()
    if jobs:
        progress = _Progress(sum(job["total"] for job in jobs))
        try:
            if args.jobs == 1:
                runs.update(_train_in_process(jobs, progress))
            else:
                runs.update(_train_in_workers(jobs, args.jobs, progress, out / "logs"))
        finally:
            progress.close()
    results["seconds"].update(training=time.perf_counter() - tic, jobs=args.jobs,
                              threads_per_job=max(1, _cores() // args.jobs) if args.jobs > 1 else torch.get_num_threads())
    trained = {_run_key(job): job for job in jobs}
    for key, job in trained.items():
        if isinstance(runs.get(key), Path):
            m = _metrics(runs[key])
            results["seconds"]["runs"][key] = {"data": m.get("data_seconds"), "train": m.get("train_seconds"),
                                               "wall": job.get("wall")}

    # 3. evaluate and draw, task by task, here
    tic = time.perf_counter()
    for task in tasks:
        keys = {seed: {label: f"{task}/{label}/seed{seed}" for label in MODELS} for seed in seeds}
        failed = [runs[k] for by_label in keys.values() for k in by_label.values() if isinstance(runs[k], Exception)]
        per_seed = {}
        try:
            if failed:
                raise failed[0]
            for seed in seeds:
                figs = None if args.no_figures or seed != args.seed else out / "figures"
                per_seed[str(seed)] = evaluate_task(task, {label: runs[k] for label, k in keys[seed].items()}, figs)
        except (FileNotFoundError, ImportError) as err:   # its data (real) or packages (pixels) are missing
            print(f"  {task:7s} SKIPPED: {err}", flush=True)
            results.setdefault("skipped", {})[task] = str(err)
            continue
        row = dict(per_seed[str(args.seed)])
        if len(per_seed) > 1:
            row["per_seed"] = per_seed
        stage = {"data": None, "train": {}, "evaluate": 0.0, "figures": 0.0}
        for seed, by_label in keys.items():
            for label, key in by_label.items():
                timing = results["seconds"]["runs"].get(key)
                if timing:
                    stage["data"] = (stage["data"] or 0.0) + (timing["data"] or 0.0)
                    stage["train"][label] = stage["train"].get(label, 0.0) + (timing["train"] or 0.0)
            for part in ("evaluate", "figures"):
                stage[part] += per_seed[str(seed)]["seconds"][part]
        row.pop("seconds", None)
        results["tasks"][task] = row
        results["seconds"]["tasks"][task] = stage
        print(f"  {task:7s} evaluated ({stage['evaluate']:.1f} s)"
              + (f", figures ({stage['figures']:.1f} s)" if not args.no_figures else ""), flush=True)
    results["seconds"]["evaluation"] = time.perf_counter() - tic
    results["seconds"]["total"] = time.perf_counter() - start
    write_json(out / "results.json", results)
    tables = tables_markdown(results)
    atomic_write(out / "tables.md", lambda tmp: Path(tmp).write_text(tables))
    print("\n" + tables)
    print(f"{'QUICK smoke run: ' if args.quick else ''}total {results['seconds']['total']:.1f} s; "
          f"wrote {out / 'results.json'}, {out / 'tables.md'}" + ("" if args.no_figures else f", {out / 'figures'}/"))
    if args.update_readme:
        readme.update_section("results", tables)
        print("updated README.md")
    return results


if __name__ == "__main__":
    main()
