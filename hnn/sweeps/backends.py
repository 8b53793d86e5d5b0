"""Where a sweep's units of work train: in this process, in worker processes here, or as Ray tasks
(on this machine or a cluster). ``hnn.sweeps.sweep.train_jobs`` chooses one and reads what it yields: each
``(job, run folder or exception)`` as its unit finishes; a unit is a list of ``hnn.sweeps.sweep.Job`` (one
run alone, or a group that trains as one program, ``hnn.sweeps.group_runs``).

A worker whose parent process is gone stops by itself, and on an interrupt the runs not started are
cancelled and the workers stopped (``hnn.sweeps.stopping``). Ray is optional and imported only here, by
``import_ray``, which says what to install.
"""
from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
import os
import socket
import sys
from pathlib import Path

from .. import names
from ..errors import DivergenceError
from .group_runs import run_group_task, train_group
from ..runs import COMPLETE, run_experiment
from ..tasks import repo_root, run_task
from .stopping import in_worker, stop_pool, worker_start
from ..threads import cores, torch_threads
from .. import progress as progress_lines

BACKENDS = names.BACKENDS
RAY_INSTALL = 'pip install -e ".[ray]"'


# seconds between the lines that say how far a long run is, where no bar is drawn (no terminal)
HEARTBEAT = progress_lines.HEARTBEAT


def _group_outcomes(unit: list, outcomes: list[dict]):
    """``(job, folder or exception)`` of each job of a group from ``hnn.sweeps.group_runs.run_group_task``'s outcomes."""
    for job, outcome in zip(unit, outcomes):
        yield job, (Path(outcome["folder"]) if "folder" in outcome else DivergenceError(outcome["error"])
                    if outcome.get("diverged") else RuntimeError(outcome["error"]))


def train_here(units: list[list], data: dict, tick, progress):
    """Yield ``(job, folder or exception)`` for each run trained here, one unit after another, on
    the datasets built; the sweep's ``hnn.progress.Ticker`` ``tick`` moves with every step of a lone run,
    after a group (where it draws no bar, a lone run says its step every ``HEARTBEAT`` seconds, with
    ``progress``'s tag)."""
    for unit in units:
        if len(unit) > 1:
            try:
                outcomes = train_group([job.config for job in unit],
                                                   [data[job.config.dataset_key()] for job in unit])
            except Exception as err:        # the whole group failed: each of its runs is reported
                outcomes = [err] * len(unit)
            for job, outcome in zip(unit, outcomes):
                tick.advance(job.steps)
                yield job, outcome
            continue
        job, done, beat = unit[0], [0], progress_lines.Heartbeat(HEARTBEAT)

        def advance(step: int, total: int, done=done, beat=beat, job=job) -> None:
            tick.advance(step - done[0])
            done[0] = step
            if not tick.drawn and (line := beat.due(step, total)):        # no bar: a line now and then
                tick.say(f"  {progress.tag()} {job.key}: {line}")
        try:
            outcome = run_experiment(job.config, data[job.config.dataset_key()], on_step=advance)
        except Exception as err:        # one bad run must not end the sweep (KeyboardInterrupt still does)
            outcome = err
        tick.advance(job.steps - done[0])
        yield job, outcome


def run_reported(task: str, values, key: str, threads: int | None = None) -> str:
    """``hnn.tasks.run_task`` in a worker process, saying every ``HEARTBEAT`` seconds how far its run is
    (``key: step s of total, about m min left``) where its output is not a terminal (a log: a long run in
    a worker is not silent until it ends; in a terminal the sweep's bar follows the runs)."""
    if sys.stdout.isatty():
        return run_task(task, values, threads)
    beat = progress_lines.Heartbeat(HEARTBEAT)

    def advance(step: int, total: int) -> None:
        if line := beat.due(step, total):
            print(f"  {key}: {line}", flush=True)
    return run_task(task, values, threads, on_step=advance)


def _submit(unit: list) -> tuple:
    """The worker call of a unit: ``(function, *arguments)`` before the thread count."""
    if len(unit) == 1:
        return run_reported, unit[0].task, unit[0].fields(), unit[0].key
    return run_group_task, unit[0].task, [job.fields() for job in unit]


def _unit_results(unit: list, result):
    """``(job, folder or exception)`` of each job of a finished unit (``result``: its worker's return)."""
    if isinstance(result, BaseException):
        for job in unit:
            yield job, result
    elif len(unit) == 1:
        yield unit[0], Path(result)
    else:
        yield from _group_outcomes(unit, result)


def train_in_pool(units: list[list], n_jobs: int, threads: int):
    """Yield ``(job, folder or exception)`` as ``n_jobs`` worker processes of ``threads`` threads
    finish them; on an interrupt (or any exception) the runs not started are cancelled and the
    workers stopped, not waited for."""
    for unit, result in _pool_results([(unit, *_submit(unit), threads) for unit in units], n_jobs):
        yield from _unit_results(unit, result)


def _pool_results(calls: list[tuple], n_jobs: int):
    """Yield ``(owner, result or exception)`` as ``n_jobs`` worker processes finish each ``(owner, function,
    *arguments)`` of ``calls``; on an interrupt (or any exception) the calls not started are cancelled and the
    workers stopped (``hnn.sweeps.stopping``), not waited for."""
    context = multiprocessing.get_context("spawn")     # a fresh interpreter: no torch state copied by fork
    pool = concurrent.futures.ProcessPoolExecutor(n_jobs, mp_context=context, initializer=worker_start,
                                                  initargs=(os.getpid(),))
    try:
        futures = {pool.submit(in_worker, *call): owner for owner, *call in calls}
        for future in concurrent.futures.as_completed(futures):
            error = future.exception()
            yield futures[future], error if error is not None else future.result()
    except BaseException:
        stop_pool(pool)
        raise
    pool.shutdown()


def train_on_ray(units: list[list], threads: int, address: str | None):
    """Yield ``(job, folder or exception)`` as Ray tasks of ``threads`` CPUs each finish them; a run
    whose node dies is retried once elsewhere, then reported."""
    with _ray_session(threads, address) as (ray, options):
        remotes = {}
        refs = {}
        for unit in units:
            function, *arguments = _submit(unit)
            gpus = 1 if unit[0].config.device.startswith("cuda") else 0     # a group is one program: one GPU
            remote = remotes.setdefault((function, gpus), ray.remote(function).options(**options, num_gpus=gpus))
            refs[remote.remote(*arguments, threads)] = unit
        for unit, result in _ray_results(ray, refs):
            for job, folder in _unit_results(unit, result):
                if isinstance(folder, Path) and not (folder / COMPLETE).is_file():
                    folder = RuntimeError(f"its run folder {folder}, written on another node, is not complete "
                                          "here: put --out on storage that every node sees at the same path")
                yield job, folder


@contextlib.contextmanager
def _ray_session(threads: int, address: str | None):
    """``(ray, task options)``: Ray joined at ``address`` (None: started here with this machine's cores, and shut
    down after), checked to have a node of ``threads`` CPUs; each task ``threads`` CPUs, retried once."""
    ray = import_ray()
    started = not ray.is_initialized()
    if started:
        if address is not None:
            probe(address)
        ray.init(address=address, num_cpus=None if address else cores(), include_dashboard=False,
                 log_to_driver=False, logging_level="ERROR")
    try:
        biggest = max((node["Resources"].get("CPU", 0) for node in ray.nodes() if node["Alive"]), default=0)
        if biggest < threads:      # Ray would queue such a task forever
            raise ValueError(f"each task asks Ray for {threads} CPUs ({cores()} cores here // --jobs), but the "
                             f"largest Ray node has {biggest:g}; raise --jobs so each task takes fewer threads")
        # the workers import this checkout's hnn, at the same path on every node (docs/sweeps.md)
        root = str(Path(__file__).resolve().parent.parent)
        env = {"PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])),
               "HNN_REPO": str(repo_root()), "OMP_NUM_THREADS": str(threads)}
        yield ray, dict(num_cpus=threads, max_retries=1, runtime_env={"env_vars": env})
    finally:
        if started:
            ray.shutdown()


def _ray_results(ray, refs: dict):
    """Yield ``(refs' value, result or exception)`` as each Ray task of ``refs`` finishes: the task's own
    exception where it raised (its remote traceback as a note), Ray's where its worker or node died."""
    while refs:
        [ref], _ = ray.wait(list(refs), num_returns=1)
        owner = refs.pop(ref)
        try:
            result = ray.get(ref)
        except ray.exceptions.RayError as err:
            cause = getattr(err, "cause", None)
            if isinstance(cause, Exception):
                cause.add_note(str(err))
            result = cause if isinstance(cause, Exception) else err
        yield owner, result


def _call(function, cell, threads: int):
    """``function(cell)`` on ``threads`` torch threads (a worker's or Ray task's body)."""
    with torch_threads(threads):
        return function(cell)


def map_cells(function, cells: list, jobs: int = 1, backend: str = "local", address: str | None = None,
              threads: int = 1):
    """Yield ``(index, result or exception)`` of ``function(cell)`` for each of ``cells`` as it finishes, on
    ``threads`` torch threads: here, one after another (``jobs`` 1); in ``jobs`` worker processes here; or, with
    ``backend='ray'``, as Ray tasks of ``threads`` CPUs each (on this machine, or the cluster at ``address``).
    The generic map of a study's measuring, where ``train_jobs`` is its training's: ``function`` must be a
    module's function and each cell picklable. A cell's exception is yielded in its place; an interrupt cancels
    the cells not started and stops the workers."""
    if backend not in BACKENDS:
        raise ValueError(f"backend {backend!r}: choose one of {', '.join(BACKENDS)}")
    if not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs={jobs!r}: the worker processes, an integer >= 1")
    if backend == "ray":
        with _ray_session(threads, address) as (ray, options):
            remote = ray.remote(_call).options(**options)
            yield from _ray_results(ray, {remote.remote(function, cell, threads): i for i, cell in enumerate(cells)})
        return
    if jobs == 1:
        for i, cell in enumerate(cells):
            try:
                result = _call(function, cell, threads)
            except Exception as err:        # one bad cell must not end the map (KeyboardInterrupt still does)
                result = err
            yield i, result
        return
    yield from _pool_results([(i, _call, function, cell, threads) for i, cell in enumerate(cells)], jobs)


def import_ray():
    """The ``ray`` module, or an ImportError that says what to install."""
    try:
        import ray
    except ImportError as err:
        raise ImportError(f"--backend ray needs Ray, which is not installed here: {RAY_INSTALL}") from err
    return ray


def probe(address: str, timeout: float = 5.0) -> None:
    """Raise ConnectionError naming the fix when nothing answers at a ``host:port`` (or
    ``ray://host:port``) address: Ray itself would retry for minutes. Other forms (``auto``) are
    left to Ray."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit() or not host:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as err:
        raise ConnectionError(f"--ray-address {address}: nothing answers there ({err.strerror or err}); start Ray "
                              "on the head node with `ray start --head` and pass the address it prints") from err
