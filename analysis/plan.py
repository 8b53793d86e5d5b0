"""What a study will cost, said before it starts: its stages, each with a count and an estimate from measured
per-run costs, and the total on this box.

    jobs = plan.timed(jobs)                                  # each run's training, measured now
    plan.say("reproduce", [plan.training(jobs, 2), plan.Stage("evaluate", 7, "rows")], jobs=2)

A run's training estimate is its steps at the rate of that config alone on one thread over a short burst
(``training_cost``, once a config, seeds aside) and what a run costs beside its steps (``overhead``: a
one-step run of its task, timed once), set as the job's ``expected_seconds``, so the
sweep also starts the longest first and says its time left at the rate the estimates run at
(``hnn.sweeps.sweep.train_jobs``). The runs are shared over ``--jobs`` workers longest first (``schedule``). A stage
whose cost is not known before it runs (a model's measurement) is counted and timed from its first units
(``Ahead``): its lines say the time left as it goes. The estimates are for a quiet box: the plan says the load
it saw, since two torch processes of two threads each ran up to 30x slower than one (docs/speed.md#threads).
"""
from __future__ import annotations

import dataclasses
import heapq
import os
import tempfile
import time
from dataclasses import dataclass

import hnn
from hnn.progress import Rate, say_left


@dataclass
class Stage:
    """One stage of a plan: ``count`` ``unit`` of ``what``, ``seconds`` its wall-time estimate (None: timed as it
    runs) and ``how`` that estimate was made."""
    what: str
    count: int
    unit: str
    seconds: float | None = None
    how: str = ""


# the bursts of a plan's measurement of a config: one short one (a plan must cost little beside what it plans)
BURSTS, BURST_SECONDS = 1, 0.05


def timed(jobs: list, cost=None, overhead_of=None) -> list:
    """``jobs`` (``hnn.sweeps.sweep.Job``), each with its ``expected_seconds`` measured: ``cost(task, args)["seconds"]``
    (default one short burst of ``training_cost``), once per config whatever its seed, plus ``overhead_of(job)``
    (default ``overhead``), once per task; a job that has one keeps it."""
    overhead_of = overhead_of or overhead
    if cost is None:
        from hnn_analysis.training_cost import training_cost

        def cost(task, args):
            return training_cost(task, args, BURSTS, BURST_SECONDS)
    measured, overheads, out = {}, {}, []
    for job in jobs:
        if job.expected_seconds is None:
            args = {**job.config.to_dict(), "seed": 0}
            key = (job.task, tuple(sorted((k, repr(v)) for k, v in args.items() if k != "save_dir")))
            if key not in measured:
                try:
                    measured[key] = cost(job.task, args)["seconds"]
                except Exception:       # a config whose first steps fail: its run fails (and says why) in the sweep
                    measured[key] = None
            if job.task not in overheads:
                overheads[job.task] = overhead_of(job) if measured[key] is not None else 0.0
            seconds = None if measured[key] is None else measured[key] + overheads[job.task]
            job = dataclasses.replace(job, expected_seconds=seconds)
        out.append(job)
    return out


def overhead(job) -> float:
    """A run's seconds beside its steps (its data prepared, its model built, its final losses, its folder
    saved): a run of ``job``'s config of one step, in a folder of its own, timed (0 where it fails); for the
    short runs of a quick study this is most of a run."""
    from hnn.threads import torch_threads
    with tempfile.TemporaryDirectory(prefix="plan-") as tmp, torch_threads(1):
        tic = time.perf_counter()
        try:
            hnn.run_experiment(dataclasses.replace(job.config, total_steps=0, save_dir=tmp))
        except Exception:       # its run fails (and says why) in the sweep
            return 0.0
        return time.perf_counter() - tic


def schedule(seconds: list[float], workers: int) -> float:
    """The wall time of tasks of ``seconds`` on ``workers`` workers, the longest first, each to the first free worker."""
    free = [0.0] * max(1, workers)
    for s in sorted(seconds, reverse=True):
        heapq.heapreplace(free, free[0] + s)
    return max(free)


def training(jobs: list, workers: int) -> Stage:
    """The training stage of ``jobs`` (``timed`` ones) on ``workers`` processes."""
    seconds = [job.expected_seconds or 0.0 for job in jobs]
    untimed = sum(job.expected_seconds is None for job in jobs)
    return Stage("train", len(jobs), "run" if len(jobs) == 1 else "runs", schedule(seconds, workers) if jobs else 0.0,
                 "each run's steps at its config's one-thread rate, measured now"
                 + (f", on {workers} processes" if workers > 1 and len(jobs) > 1 else "")
                 + (f"; {untimed} could not be timed" if untimed else ""))


def _words(seconds: float) -> str:
    return say_left(seconds).replace(" left", "")


def say(who: str, stages: list[Stage]) -> str:
    """Print the plan, one line a stage and the total, before the study starts; returns it."""
    known = [s.seconds for s in stages if s.seconds is not None]
    lines = [f"{who}: plan on this box ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} now; other jobs on it "
             "slow every stage):"]
    for s in stages:
        estimate = ("timed as it runs, from its first units" if s.seconds is None else _words(s.seconds))
        lines.append(f"  {s.what} {s.count} {s.unit}: {estimate}" + (f" ({s.how})" if s.how and s.seconds else ""))
    if known:
        rest = " and the stages timed as they run" if len(known) < len(stages) else ""
        lines.append(f"  in all: {_words(sum(known))}{rest}")
    text = "\n".join(lines)
    print(text, flush=True)
    return text


class Ahead:
    """The time left of a stage of ``total`` units of work (``weight`` of each unit, default 1) at the rate of
    the recent past: ``tag(done_weight)`` after each unit gives ``', about 3 min left'`` (nothing before a rate)."""

    def __init__(self, total: float):
        self.total, self.rate = total, Rate(0.0, time.perf_counter())

    def tag(self, done: float) -> str:
        self.rate.add(done)
        left = self.rate.left(self.total)
        return "" if left is None or done >= self.total else f", {say_left(left)}"
