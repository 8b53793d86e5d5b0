"""Stopping a sweep: a SIGINT (Ctrl-C) or SIGTERM (``kill``, a job scheduler) to the sweep's own
process cancels the runs not started, stops the worker processes (a run in progress leaves no
folder: it is written whole or not at all), keeps every finished run, says so in one line and
exits with 128 + the signal; a worker whose parent process is gone stops by itself.

``hnn/sweeps/sweep.py`` starts its process pool's workers with ``worker_start``, submits each unit
through ``in_worker``, stops the pool with ``stop_pool`` and trains inside ``interruptible``.
"""
from __future__ import annotations

import concurrent.futures
import os
import signal
import sys
import threading
import time
from pathlib import Path

from tqdm.auto import tqdm


class Interrupted(BaseException):
    """A SIGINT or SIGTERM to the sweep's process (``signum``): like KeyboardInterrupt, not an error of a run."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(signum)

    def __str__(self) -> str:
        return signal.Signals(self.signum).name


def _raise_interrupted(signum, frame):
    raise Interrupted(signum)


_IN_RUN = threading.Event()     # in a worker: set while it trains a unit


def _worker_signal(signum, frame):
    """A worker's SIGTERM: the run in progress ends by an exception (its half-written folder is
    removed on the way out, and ``in_worker`` then exits); an idle worker exits at once."""
    if _IN_RUN.is_set():
        raise Interrupted(signum)
    os._exit(128 + signum)


def worker_start(parent: int) -> None:
    """In each worker process: the sweep's process alone answers Ctrl-C (it stops the workers),
    SIGTERM stops the worker cleanly, and the worker stops when its parent is gone (killed
    outright) instead of training on as an orphan."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _worker_signal)
    # tqdm's default lock holds a multiprocessing semaphore, registered with the sweep's resource
    # tracker; a worker stopped mid-run (os._exit) never released it, and the tracker warned of leaked
    # semaphores as the command exited. A worker's bars need no lock across processes.
    tqdm.set_lock(threading.RLock())

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(10)      # time for its run's cleanup; then out, whatever it is doing
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def in_worker(function, *arguments):
    """``function(*arguments)`` in a worker process; a SIGTERM meanwhile ends the worker once the
    run has removed what it had half written."""
    _IN_RUN.set()
    try:
        return function(*arguments)
    except Interrupted as err:
        os._exit(128 + err.signum)
    finally:
        _IN_RUN.clear()


def stop_pool(pool: concurrent.futures.ProcessPoolExecutor, grace: float = 10.0) -> None:
    """Cancel the runs not started and end the workers: SIGTERM (a run in progress cleans up), then kill."""
    workers = list((pool._processes or {}).values())      # the executor offers no public handle on them
    pool.shutdown(wait=False, cancel_futures=True)
    for worker in workers:
        if worker.is_alive():
            worker.terminate()
    deadline = time.monotonic() + grace
    for worker in workers:
        worker.join(max(0.0, deadline - time.monotonic()))
        if worker.is_alive():
            worker.kill()
            worker.join()


class interruptible:
    """While a sweep trains: SIGTERM interrupts it as Ctrl-C does, and either ends the command with
    one line (what finished and stays, what was not kept) and exit code 128 + the signal."""

    def __init__(self, runs: dict, jobs):
        self.runs, self.jobs, self.previous = runs, jobs, None

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGTERM, _raise_interrupted)
        return self

    def __exit__(self, kind, err, tb):
        if self.previous is not None:
            signal.signal(signal.SIGTERM, self.previous)
        if kind is KeyboardInterrupt or kind is Interrupted:
            signum = err.signum if kind is Interrupted else signal.SIGINT
            from ..runs import find_run     # here: the sweep's modules import this one
            # the workers are stopped by now: a run one of them finished after the last result came back is on
            # disk whole (a run folder is written atomically) and counts as kept
            for job in self.jobs:
                if job.key not in self.runs and (found := find_run(job.config)) is not None:
                    self.runs[job.key] = found
            kept = sum(isinstance(run, Path) for run in self.runs.values())
            print(f"\ninterrupted ({signal.Signals(signum).name}): kept the {kept} finished run"
                  f"{'' if kept == 1 else 's'}; the {len(self.jobs) - len(self.runs)} not finished were cancelled or "
                  "stopped, leaving no run folder (rerunning the same command trains only those, each run that "
                  "was in progress from its last training checkpoint)", file=sys.stderr, flush=True)
            raise SystemExit(128 + signum)
        return False
