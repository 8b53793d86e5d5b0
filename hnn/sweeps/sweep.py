"""Training sweeps: a list of run configs mapped to trained run folders, in this process, in worker
processes here, or as Ray tasks (on this machine or a cluster), longest first, with one progress bar.

    jobs = [sweep.Job("spring/hnn/seed0", "spring", tasks.task_config("spring", {"seed": 0}))]
    runs, jobs = sweep.reuse(jobs)                         # saved runs found by their config, the rest
    trained, seconds = sweep.train_jobs(jobs, n_jobs=2, log_dir=out / "logs", backend="ray")

A run is found again by its config (``hnn.runs.find_run``): a rerun trains only what is missing, and
a saved run that does not load is reported by name and trained again. Each dataset is built once,
here, before the map (the cached ones are then read by every worker). A run that fails is
reported by name with its error and the others go on; ``exit_if_failed`` ends the command with
code 1 and the list. A task that cannot run here at all (missing data or optional packages) is
skipped with its reason once. Where the units train is ``hnn.sweeps.backends``'s (Ray is optional and
imported only for ``backend="ray"``); a command's flags that choose it are ``hnn.sweeps.flags``'s.

A SIGINT (Ctrl-C) or SIGTERM (``kill``, a job scheduler) to the sweep's own process cancels the
runs not started, stops the workers (a run in progress leaves no folder: it is written whole or
not at all), keeps every finished run, says so in one line and exits with 130 or 143; a worker
whose parent process is gone stops by itself.

With ``group="auto"`` the runs that can train as one program (``hnn.sweeps.group_runs.unit_key``: one
task, kind and width, seeds and fractions apart) train as groups, each one unit of work for the pool
or Ray (one GPU each on Ray), each model still saved as its own run folder: on the CPU those narrow
enough for grouping to pay (``GROUP_MAX_WIDTH``, measured by ``analysis/benchmarks/benchmark.py --jobs
group``), on a GPU all of them (``DEVICE_GROUP_MAX``).
"""
from __future__ import annotations

import json
import statistics
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from .backends import BACKENDS, train_here, train_in_pool, train_on_ray
from .. import names
from ..progress import Rate, Ticker, say_left
from .group_runs import drop_spent_checkpoints, unit_key
from ..runs import diverged_record, find_run, load_run, partial_checkpoint, record_divergence
from ..tasks import task_spec
from ..config import RunConfig
from ..errors import DivergenceError
from .stopping import interruptible
from ..threads import cores, torch_threads

GROUP_MODES = names.GROUP_MODES
# Grouped spring HNN steps against separate runs (benchmark --jobs group --quick, shared machine,
# 1 thread, two runs): 2.3-2.6x at width 16 with G 4 and 3.1-3.4x with G 16; 1.3x at width 64
# with G 4 but 0.9-1.4x with G 16; 0.6-0.7x at width 200 with G 4 and 16. A group's activations
# (G x rows x width) outgrow the cache that a lone run's stay in: groups stop at this many hidden
# units in all (16 models of width 16, 4 of width 64) and at this width
GROUP_HIDDEN_UNITS = 256
GROUP_MAX_WIDTH = 64
# on an accelerator a paper-sized step is launch-bound, and a group of K models costs about one model's
# step up to K ~ 1000 (docs/gpu.md): groups of any width, up to this many models
DEVICE_GROUP_MAX = 1024
# what a dataset raises when its task cannot run here: missing data or optional packages
_CANNOT_RUN = (FileNotFoundError, ImportError)


@dataclass
class Job:
    """One run of a sweep: its ``key`` (``row/kind/seed<seed>``), its task and its config;
    ``expected_seconds``, its training time where the caller knows it (an earlier run of its kind),
    orders the sweep longest first where the task's relative cost cannot tell its kinds apart."""
    key: str
    task: str
    config: RunConfig
    expected_seconds: float | None = None

    @property
    def steps(self) -> int:
        """Optimizer steps (the loop runs total_steps + 1)."""
        return self.config.total_steps + 1

    def fields(self) -> dict:
        """The config as a worker elsewhere receives it: ``save_dir`` absolute (a Ray worker runs
        in a folder of its own; save_dir is not part of a run's identity, so its folder is the same)."""
        return {**self.config.to_dict(), "save_dir": str(Path(self.config.save_dir).resolve())}


class Progress:
    """Work done of work to do and the time so far, the tag every progress line of a long command
    starts with: ``[3/21, 45 s]``. One per stage (a sweep's runs, a study's measurements)::

        progress = sweep.Progress(len(units))
        for unit in units:
            ...
            print(f"  {progress.advance()} {unit} measured", flush=True)
    """

    def __init__(self, total: int):
        self.total, self.done, self.start = total, 0, time.perf_counter()

    def tag(self) -> str:
        """``[done/total, seconds so far]``."""
        return f"[{self.done}/{self.total}, {time.perf_counter() - self.start:.0f} s]"

    def advance(self, n: int = 1) -> str:
        """Count ``n`` more done; the tag after it."""
        self.done += n
        return self.tag()


class RunFailed(Exception):
    """A run that raised or whose worker died: its ``key``, the error ``message`` and the ``log``
    file holding its traceback (None when there is none). ``diverged``: the model itself failed
    (an ``hnn.DivergenceError``: a loss that is no longer finite, a field that cannot be solved), a
    result of its config that a rerun repeats, which a study may report as such."""

    def __init__(self, key: str, message: str, log: Path | None = None, diverged: bool = False):
        self.key, self.message, self.log, self.diverged = key, message, log, diverged
        super().__init__(f"{key}: {message}" + (f" (log: {log})" if log else ""))


def _recorded_failure(job: Job) -> RunFailed | None:
    """The ``RunFailed`` a sweep recorded for ``job`` (``diverged_record``), or None (none, or unreadable)."""
    record = diverged_record(job.config)
    try:
        message = json.loads(record.read_text())["message"]
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError) as err:
        print(f"  {job.key}: its record of a failed run, {record}, cannot be read ({err}); training it again", flush=True)
        return None
    return RunFailed(job.key, message, diverged=True)


def reuse(jobs: list[Job], diverged: bool = False) -> tuple[dict, list[Job]]:
    """``({key: saved run folder}, jobs left to train)``, quietly for the runs found (``say_reused`` is the
    caller's one line for them); a saved run that does not load is reported by name and left to train
    again (its folder is replaced), and a job whose run was killed mid-training is named with its checkpoint. ``diverged``: a job whose run a sweep saw fail in training
    (``diverged_record``) maps to that ``RunFailed`` instead of training again (a table that reports such
    a failure as its cell; delete the record, or set the config's ``force``, to train it again)."""
    found, todo = {}, []
    for job in jobs:
        folder = find_run(job.config)
        try:
            if folder is not None:
                load_run(folder)
                found[job.key] = folder
                continue
        except (RuntimeError, OSError, ValueError, KeyError) as err:
            print(f"  {job.key}: {err}; training it again", flush=True)
        failed = _recorded_failure(job) if diverged and not job.config.force else None
        if failed is not None:
            found[job.key] = failed
            print(f"  {job.key} failed in training in an earlier sitting, reused as such "
                  f"({failed.message.split(':')[0]}; delete {diverged_record(job.config)} to train it again)", flush=True)
            continue
        if partial_checkpoint(job.config).exists():     # a run killed mid-training (hnn.runs)
            print(f"  {job.key} has a training checkpoint: trained alone, it resumes there", flush=True)
        todo.append(job)
    return found, todo


# a reuse line names the runs still to train when there are at most this many
NAMED = 8


def say_reused(who: str, found: dict, todo: list[Job]) -> str:
    """Print one line for a study's saved runs, however many: ``'reproduce: 64 runs reused, 2 to train:
    spring/hnn/seed3, pend/hnn/seed3'`` (the runs to train named when there are at most ``NAMED``)."""
    line = (f"{who}: {len(found)} run{'' if len(found) == 1 else 's'} reused, {len(todo)} to train"
            + (": " + ", ".join(job.key for job in todo) if 0 < len(todo) <= NAMED else ""))
    print(line, flush=True)
    return line


def plan_units(jobs: list[Job], group: str = "auto") -> list[list[Job]]:
    """``jobs`` as units of work: the jobs of one ``hnn.sweeps.group_runs.unit_key`` as groups, each other job
    alone. ``group="all"``: every kind's groups (all but the pixel kinds); ``"auto"``: on the CPU only the
    closed-form groups of the paper's tanh-MLP kinds (a CPU sweep trains every other kind alone, as the
    docs' numbers were made), on another device every kind's; ``"off"``: none. On the CPU a group is at
    most ``GROUP_MAX_WIDTH`` wide and ``GROUP_HIDDEN_UNITS`` hidden units in all, elsewhere up to
    ``DEVICE_GROUP_MAX`` models of any width."""
    if group not in GROUP_MODES:
        raise ValueError(f"group {group!r}: choose one of {', '.join(GROUP_MODES)}")
    units, groups = [], {}
    for job in jobs:
        on_cpu = job.config.device == "cpu"
        key = unit_key(job.config) if group != "off" else None
        if key is not None and group == "auto" and on_cpu and key[0] != "closed_form":
            key = None
        if key is None or (on_cpu and job.config.hidden_dim > GROUP_MAX_WIDTH):
            units.append([job])
        else:
            groups.setdefault(key, []).append(job)
    for members in groups.values():
        on_cpu = members[0].config.device == "cpu"
        size = max(1, GROUP_HIDDEN_UNITS // members[0].config.hidden_dim) if on_cpu else DEVICE_GROUP_MAX
        units += [members[i:i + size] for i in range(0, len(members), size)]
    return units


def longest_first(units: list[list[Job]]) -> list[list[Job]]:
    """``units`` longest first, so that the last to finish is a short one: a run costs its
    ``expected_seconds``, or else its task's relative cost times its steps, put in seconds at the
    median rate of the runs that know theirs; a group about its longest member's time, twice (the
    models step together)."""
    def rough(job: Job) -> float:
        return task_spec(job.task).cost * job.steps
    rates = [job.expected_seconds / rough(job) for unit in units for job in unit if job.expected_seconds]
    rate = statistics.median(rates) if rates else 1.0

    def cost(unit: list[Job]) -> float:
        longest = max(job.expected_seconds or rough(job) * rate for job in unit)
        return longest * (1 if len(unit) == 1 else 2)
    return sorted(units, key=cost, reverse=True)


def _build_datasets(jobs: list[Job], tick: Ticker) -> tuple[dict, dict, dict]:
    """Each distinct dataset of ``jobs`` built once: ``({dataset key: data}, {dataset key: seconds},
    {task: the error of a task that cannot run here})``."""
    data, seconds, skipped = {}, {}, {}
    for job in jobs:
        key = job.config.dataset_key()
        if key in data or job.task in skipped:
            continue
        tic = time.perf_counter()
        try:
            data[key] = job.config.dataset()
        except _CANNOT_RUN as err:
            skipped[job.task] = err
            tick.say(f"  {job.task:11s} cannot run here, skipping all its runs: {err}")
            continue
        seconds[key] = time.perf_counter() - tic
    return data, seconds, skipped


def _failure(job: Job, err: BaseException, log_dir: Path, tick: Ticker, tag: str = "") -> RunFailed:
    """Report a failed run by name with its error, its traceback in ``<log_dir>/<key>.log``."""
    log = Path(log_dir) / f"{job.key.replace('/', '-')}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    log.write_text("".join(traceback.format_exception(err)))
    failed = RunFailed(job.key, f"{type(err).__name__}: {err}", log, diverged=isinstance(err, DivergenceError))
    tick.say(f"  {tag}{job.key} FAILED: {failed.message} (log: {log})")
    if failed.diverged:         # a result of the config: recorded for a later sitting (reuse(..., diverged=True))
        record_divergence(job.config, err)
    return failed


def _metrics(folder: Path) -> dict:
    try:
        return json.loads((Path(folder) / "metrics.json").read_text())
    except (OSError, ValueError):
        return {}


def train_jobs(jobs: list[Job], n_jobs: int, log_dir: Path, backend: str = "local",
               ray_address: str | None = None, group: str = "off", device: str | None = None,
               on_done: Callable[[Job, Path | BaseException], None] | None = None) -> tuple[dict, dict]:
    """Train ``jobs``; ``({key: run folder or exception}, seconds)``.

    ``backend="local"``: here (``n_jobs`` 1, on one thread, the caller's count restored after) or in
    ``n_jobs`` worker processes with ``cores // n_jobs`` threads each; ``"ray"``: one Ray task per run with as many threads (and CPUs asked of
    Ray), on the Ray at ``ray_address`` (None: a local one, or the one already initialized). A run
    that fails maps to a ``RunFailed``, one whose task cannot run here to that task's error.
    ``seconds`` holds the wall time, the backend, jobs, threads per job and each run's data /
    train / wall seconds (a dataset's build here counts for the first run that uses it).
    ``group``: ``"auto"`` trains the runs that can share one program as groups (``plan_units``).
    ``device``: every run's torch device (None: each config's own); on Ray a run or group on a GPU
    asks for one whole GPU. ``on_done(job, outcome)``: called here as each run finishes (its folder,
    or its ``RunFailed``), while the workers train on: a study that keeps each result as it comes.
    """
    if device is not None:
        jobs = [replace(job, config=replace(job.config, device=device)) for job in jobs]
    if backend not in BACKENDS:
        raise ValueError(f"backend {backend!r}: choose one of {', '.join(BACKENDS)}")
    if ray_address is not None and backend != "ray":
        raise ValueError(f"ray_address {ray_address!r} is only used with backend='ray'; pass that or drop it")
    if n_jobs < 1:
        raise ValueError(f"n_jobs {n_jobs}: must be at least 1 (1 = train in this process)")
    in_process = backend == "local" and n_jobs == 1
    # here, one thread as a train.py (docs/speed.md#threads): on a shared box a second slows runs many times over
    threads = 1 if in_process else max(1, cores() // n_jobs)
    tic, done, per_run = time.perf_counter(), {}, {}
    if group not in GROUP_MODES:
        raise ValueError(f"group {group!r}: choose one of {', '.join(GROUP_MODES)}")
    # one bar of the sweep's steps where someone watches (hnn.progress.Ticker); its runs say their own lines
    with torch_threads(threads if in_process else None), interruptible(done, jobs), \
            Ticker(sum(job.steps for job in jobs), "sweep", lines=False) as tick:
        data, data_seconds, skipped = _build_datasets(jobs, tick)
        done.update({job.key: skipped[job.task] for job in jobs if job.task in skipped})
        todo = [job for job in jobs if job.task not in skipped]
        units = longest_first(plan_units(todo, group))
        if not in_process:
            data.clear()        # the workers read the cached datasets themselves
        # one line per run, with the runs done of those to do and the time so far: the bar above is
        # drawn only on a terminal, and a long run (thousands of steps) leaves it still for minutes
        progress = Progress(len(todo))
        results = (train_here(units, data, tick, progress) if in_process else train_in_pool(units, n_jobs, threads)
                   if backend == "local" else train_on_ray(units, threads, ray_address))
        if todo:
            tick.say(f"  {progress.tag()} training {len(todo)} run{'s' if len(todo) != 1 else ''} in "
                      f"{len(units)} unit{'s' if len(units) != 1 else ''} of work")
        # the time left of the whole sweep at the recent pace (hnn.progress.Rate) of its runs' expected seconds (a
        # plan's measured costs: analysis/plan.py), else of its steps (as the bar's on a terminal)
        def weight(job: Job) -> float:
            return job.expected_seconds if all(j.expected_seconds for j in todo) else job.steps
        total, done_weight, rate = sum(weight(job) for job in todo), 0.0, Rate()
        for job, outcome in results:
            tag = progress.advance() + " "
            done_weight += weight(job)
            rate.add(done_weight)
            seconds_left = rate.left(total) if done_weight < total else None
            left = f"; the sweep: {say_left(seconds_left)}" if seconds_left is not None else ""
            tick.note(f"{progress.done}/{progress.total} runs")
            if isinstance(outcome, BaseException):
                done[job.key] = _failure(job, outcome, log_dir, tick, tag)
            else:
                done[job.key] = outcome
                diverged_record(job.config).unlink(missing_ok=True)     # trained now: no failure to recall
                metrics = _metrics(outcome)
                built = data_seconds.pop(job.config.dataset_key(), 0.0)
                per_run[job.key] = {"data": built + (metrics.get("data_seconds") or 0.0),
                                    "train": metrics.get("train_seconds")}
                tick.say(f"  {tag}{job.key} trained {outcome} ({metrics.get('train_seconds', 0):.1f} s){left}")
            if not in_process:
                tick.advance(job.steps)
            if on_done is not None:
                on_done(job, done[job.key])
    for save_dir in dict.fromkeys(str(job.config.save_dir) for job in todo):
        drop_spent_checkpoints(save_dir)       # groups killed in an earlier sitting whose runs trained since
    seconds = {"training": time.perf_counter() - tic, "backend": backend, "jobs": n_jobs,
               "threads_per_job": threads, "group": group, "runs": per_run}
    return done, seconds


def failures(outcomes: dict) -> list[RunFailed]:
    """The runs of a ``train_jobs`` result that failed (not those whose task cannot run here)."""
    return [err for err in outcomes.values() if isinstance(err, RunFailed)]


def exit_if_failed(outcomes: dict) -> None:
    """End the command with code 1 and the list of failed runs, if any (call it after writing
    what did train, so a rerun of the same command trains only what is missing)."""
    failed = failures(outcomes)
    if failed:
        print(f"{len(failed)} run{'s' if len(failed) > 1 else ''} failed; rerunning the same command trains only "
              "what is missing:\n" + "\n".join(f"  {err}" for err in failed), file=sys.stderr, flush=True)
        raise SystemExit(1)
