"""Training sweeps: a list of runs trained in this process, in worker processes here, or as
Ray tasks (on this machine or a cluster), longest first, with one progress line for the whole
sweep. ``reproduce.py`` and the other sweeps build the jobs and call ``train_jobs``:

    runs, seconds = train_jobs(jobs, n_jobs=2, log_dir=out / "logs", backend="ray")

A job is a dict: ``task`` (``experiment-<task>``), ``row`` (the table row it belongs to),
``label`` (the run's label; ``baseline`` adds ``--baseline``), ``seed``, ``runs_dir`` (its
``--save_dir``), ``steps`` (``--total_steps``, or None for the task's), ``extra_argv`` (more
``train.py`` flags) and ``total`` (its optimizer steps, for the progress line). Every run goes
through its task's own ``train.py`` and saves its folder under ``runs_dir``, so a rerun reuses it
by its args whatever trained it. Worker processes run ``train_worker.py``, which sets the thread
count before torch is imported.

A run that fails is reported by name with its error and the others go on; ``exit_if_failed``
ends the command with code 1 and the list. A task that cannot run here at all (missing data or
optional packages) is skipped with its reason once. Ray is optional and only this module imports
it, when ``backend="ray"``; ``add_backend_flags`` and ``check_backend`` give a command the flags.
"""
from __future__ import annotations

import json
import logging
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import traceback
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
    # the paper's pair keeps the original's flags (--baseline, or nothing), so their runs stay reusable
    kind = ["--baseline"] if label == "baseline" else ([] if label == "hnn" else ["--model", label])
    argv = ["--save_dir", str(runs_dir), "--seed", str(seed)] + kind
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
# the same, as a worker's status file names them
_CANNOT_RUN_TYPES = {"FileNotFoundError": FileNotFoundError, "ImportError": ImportError,
                     "ModuleNotFoundError": ImportError}
_POLL = 0.3          # seconds between looks at the running workers


class RunFailed(Exception):
    """A run that raised, exited non-zero or was killed: its ``key`` (row/label/seed), the error
    ``message`` and the ``log`` file holding its output or traceback (None when there is none)."""

    def __init__(self, key: str, message: str, log: Path | None = None):
        self.key, self.message, self.log = key, message, log
        super().__init__(f"{key}: {message}" + (f" (log: {log})" if log else ""))


def _failed(job: dict, err: Exception, failed_tasks: dict, progress) -> Exception:
    """Record a run that cannot run here; its task's reason is printed once per job, not per run."""
    if job["task"] not in failed_tasks:
        failed_tasks[job["task"]] = err
        progress.write(f"  {job['task']:11s} cannot run here, skipping all its runs: {err}")
    return failed_tasks[job["task"]]


def _fail(job: dict, message: str, log: Path | None, progress: _Progress) -> RunFailed:
    """Report a failed run by name with its error; the sweep goes on with the others."""
    err = RunFailed(_run_key(job), message, log)
    progress.finish(err.key, job["total"], f"  {job['row']:11s} {job['label']:8s} seed {job['seed']} FAILED: "
                                           f"{message}" + (f" (log: {log})" if log else ""))
    return err


def _log_path(log_dir: Path, key: str) -> Path:
    return Path(log_dir) / f"{key.replace('/', '-')}.log"


def _train_in_process(jobs: list[dict], progress: _Progress, log_dir: Path) -> dict:
    """Train ``jobs`` one after another here; ``{key: folder or exception}``. A run that fails
    leaves its traceback in ``<log_dir>/<row>-<label>-seed<seed>.log``."""
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
        except (Exception, SystemExit) as err:
            # SystemExit too: a bad flag in a job's extra_argv makes argparse exit, and one bad run
            # must not end the sweep (KeyboardInterrupt still does)
            log = _log_path(log_dir, key)
            log.parent.mkdir(parents=True, exist_ok=True)
            log.write_text(traceback.format_exc())
            message = f"exit {err.code}" if isinstance(err, SystemExit) else f"{type(err).__name__}: {err}"
            done[key] = _fail(job, message, log, progress)
            continue
        job["wall"] = time.perf_counter() - tic
        progress.finish(key, job["total"], _summary(job, directory, job["wall"]))
        done[key] = directory
    return done


# ----------------------------------------------------------------------------------------------
# worker processes: here (local) or as Ray tasks
#
# Both run train_worker.py in a fresh process, so the thread count is set before torch is
# imported. _ray_run and the helpers it calls (_child_env, _read_status, _tail) run inside Ray's
# workers: they use the standard library only, since Ray ships them by value and a Ray worker
# must not import an hnn other than this checkout's.


def _child_env(environ, threads: int, package_root: str) -> dict:
    """The environment of a worker: ``threads`` OpenMP / MKL threads, and this checkout's hnn first on the path."""
    env = dict(environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    env["PYTHONPATH"] = os.pathsep.join([package_root] + [p for p in [environ.get("PYTHONPATH")] if p])
    return env


def _read_status(path: Path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}


def _tail(path: Path, lines: int = 15) -> str:
    """The last ``lines`` lines of a worker's log ('' when it cannot be read)."""
    try:
        return "".join(Path(path).read_text(errors="replace").splitlines(keepends=True)[-lines:])
    except OSError:
        return ""


def _ray_run(script: str, worker_argv: list[str], threads: int, package_root: str, cwd: str, log: str) -> dict:
    """One run as a Ray task: ``train_worker.py worker_argv`` in a child process of this Ray
    worker, its output in ``log``. Returns the outcome as the local workers report it:
    ``{"returncode", "status" (the worker's last status), "tail" (of the log), "node"}``.

    The driver's working folder is used when this node has it, so relative paths in the argv mean
    the same here (a run's ``--save_dir`` must not change: reuse compares it).
    """
    status = Path(worker_argv[worker_argv.index("--status") + 1])
    for folder in (Path(log).parent, status.parent):
        folder.mkdir(parents=True, exist_ok=True)
    # a node whose checkout sits elsewhere runs the installed package's worker instead
    cmd = [sys.executable, script] if os.path.isfile(script) else [sys.executable, "-m", "hnn_analysis.train_worker"]
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd + list(worker_argv), env=_child_env(os.environ, threads, package_root),
                                cwd=cwd if os.path.isdir(cwd) else None, stdout=out, stderr=subprocess.STDOUT)
        try:
            proc.wait()
        finally:
            # cancelled (ray.cancel raises KeyboardInterrupt here): the run must not outlive its task
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return {"returncode": proc.returncode, "status": _read_status(status), "tail": _tail(log),
            "node": socket.gethostname()}


class _LocalPool:
    """``n`` worker processes on this machine with ``threads`` threads each."""

    def __init__(self, n: int, threads: int):
        self.n, self.threads = n, threads
        self.env = _child_env(os.environ, threads, _package_root())

    def slots(self) -> int:
        return self.n

    def start(self, key: str, worker_argv: list[str], log: Path):
        out = open(log, "w")
        proc = subprocess.Popen([sys.executable, str(HERE / "train_worker.py")] + worker_argv, env=self.env,
                                stdout=out, stderr=subprocess.STDOUT)
        return proc, out, worker_argv[worker_argv.index("--status") + 1], log

    def poll(self, handle) -> dict | None:
        proc, out, status, log = handle
        if proc.poll() is None:
            return None
        out.close()
        return {"returncode": proc.returncode, "status": _read_status(status), "tail": _tail(log)}

    def stop(self, handles: list) -> None:
        for proc, out, _status, _log in handles:
            proc.kill()
            proc.wait()
            out.close()

    def close(self) -> None:
        pass


class _RayPool:
    """Each run one Ray task asking for ``threads`` CPUs, on the Ray cluster at ``address`` (None:
    a new local Ray with this machine's cores). A Ray this process has initialized already is
    used as it is, and left running."""

    def __init__(self, threads: int, address: str | None):
        ray = self.ray = _import_ray()
        self.threads, self.started = threads, False
        if not ray.is_initialized():
            quiet = {"include_dashboard": False, "logging_level": logging.ERROR, "log_to_driver": False}
            if address is None:
                ray.init(num_cpus=_cores(), **quiet)
            else:
                _probe(address)
                ray.init(address=address, **quiet)
            self.started = True
        try:
            biggest = max((node["Resources"].get("CPU", 0) for node in ray.nodes() if node["Alive"]), default=0)
            if biggest < threads:
                # Ray would queue such a task forever
                raise ValueError(f"each run asks Ray for {threads} CPUs ({_cores()} cores here // --jobs), but "
                                 f"the largest Ray node has {biggest:g}; raise --jobs so each run takes fewer threads")
            # the task function travels by value: a Ray worker needs neither this checkout nor hnn_analysis
            ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
            self.remote = ray.remote(_ray_run)
        except BaseException:
            self.close()
            raise
        self.script, self.root, self.cwd = str(HERE / "train_worker.py"), _package_root(), os.getcwd()

    def slots(self) -> int:
        # asked each time, so nodes that join during the sweep are used
        return max(1, int(self.ray.cluster_resources().get("CPU", 0)) // self.threads)

    def start(self, key: str, worker_argv: list[str], log: Path):
        # max_retries=0: a killed run is reported (a rerun trains it), not silently run again
        return self.remote.options(num_cpus=self.threads, max_retries=0, name=f"train {key}").remote(
            self.script, worker_argv, self.threads, self.root, self.cwd, str(log))

    def poll(self, ref) -> dict | None:
        ready, _ = self.ray.wait([ref], timeout=0)
        if not ready:
            return None
        try:
            return self.ray.get(ref)
        except self.ray.exceptions.RayError as err:
            # the task raised (its log could not be written, say; Ray wraps that exception as the
            # cause) or its worker died (killed, a node lost) before the run reported
            cause = getattr(err, "cause", None)
            if isinstance(cause, BaseException):
                return {"returncode": None, "status": {}, "tail": "", "error": f"{type(cause).__name__}: {cause}"}
            first = next((line for line in str(err).splitlines() if line.strip()), "")
            return {"returncode": None, "status": {}, "tail": "", "error": f"{type(err).__name__}: {first}"}

    def stop(self, refs: list) -> None:
        for ref in refs:
            self.ray.cancel(ref)
        if refs:
            # give the cancelled tasks a moment to kill their runs before Ray goes away
            self.ray.wait(refs, num_returns=len(refs), timeout=10)

    def close(self) -> None:
        if self.started:
            self.ray.shutdown()
            self.started = False


def _package_root() -> str:
    """The folder holding this process's hnn, so workers import the same code whatever the install points at."""
    return str(Path(hnn.__file__).resolve().parent.parent)


def _metrics(directory: Path) -> dict:
    try:
        return json.loads((Path(directory) / "metrics.json").read_text())
    except (OSError, ValueError):
        return {}


def _error_message(outcome: dict) -> str:
    """What went wrong in a worker that did not report a run: its error, the signal that killed
    it, or its exit code and last line of output."""
    if outcome.get("error"):
        return outcome["error"]
    state, code = outcome.get("status") or {}, outcome.get("returncode")
    if "error" in state:
        return f"{state.get('type', 'Error')}: {state['error']}"
    if code is not None and code < 0:
        try:
            return f"killed by signal {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    last = [line.strip() for line in (outcome.get("tail") or "").splitlines() if line.strip()]
    if code == 0:
        return "exited without reporting a run" + (f": {last[-1]}" if last else "")
    return f"exit {code}" + (f": {last[-1]}" if last else "")


def _settle(job: dict, outcome: dict, log: Path, failed_tasks: dict, progress: _Progress):
    """The run folder of a finished worker, or the exception that stands for its run."""
    key, state = _run_key(job), outcome.get("status") or {}
    if outcome.get("returncode") == 0 and state.get("done"):
        run = Path(state["run"])
        if (run / hnn.runs.COMPLETE).is_file():
            progress.finish(key, job["total"], _summary(job, run, job["wall"]))
            return run
        return _fail(job, f"its run folder {run}, written on {outcome.get('node', 'this machine')}, is not complete "
                          "here: put --out on storage that every node sees at the same path", log, progress)
    if state.get("type") in _CANNOT_RUN_TYPES:
        err = _failed(job, _CANNOT_RUN_TYPES[state["type"]](state["error"]), failed_tasks, progress)
        progress.finish(key, job["total"], None)
        return err
    return _fail(job, _error_message(outcome), log, progress)


def _train_in_workers(jobs: list[dict], pool, progress: _Progress, log_dir: Path) -> dict:
    """Train ``jobs`` in ``pool``'s workers, as many at once as it has slots, longest first (the
    task's ``TaskSpec.cost`` x steps); ``{key: folder or exception}``. A worker's output goes to
    ``<log_dir>/<row>-<label>-seed<seed>.log``; a run that fails is reported and the rest go on.
    """
    queue = sorted(jobs, key=lambda j: hnn.task_spec(j["task"]).cost * j["total"], reverse=True)
    running, done, failed_tasks = {}, {}, {}
    log_dir = Path(log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    # beside the logs: Ray workers on other nodes write their progress there (shared storage)
    with tempfile.TemporaryDirectory(prefix=".status-", dir=log_dir) as status_dir:
        try:
            while queue or running:
                for job in [j for j in queue if j["task"] in failed_tasks]:
                    queue.remove(job)
                    done[_run_key(job)] = failed_tasks[job["task"]]
                    progress.finish(_run_key(job), job["total"], None)
                slots = pool.slots() if queue else 0
                while queue and len(running) < slots:
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
                    status, log = Path(status_dir) / f"{key.replace('/', '-')}.json", _log_path(log_dir, key)
                    argv = ["--threads", str(pool.threads), "--status", str(status), "--task", job["task"], "--"]
                    argv += _train_argv(job["task"], job["label"], job["runs_dir"], job["seed"], job["steps"],
                                        job["extra_argv"])
                    running[key] = (job, pool.start(key, argv, log), status, log, time.perf_counter())
                    progress.update(key, 0, job["total"])
                time.sleep(_POLL)
                for key, (job, handle, status, log, tic) in list(running.items()):
                    outcome = pool.poll(handle)
                    if outcome is None:
                        state = _read_status(status)
                        if "step" in state:
                            progress.update(key, state["step"], state["total"])
                        continue
                    del running[key]
                    job["wall"] = time.perf_counter() - tic
                    done[key] = _settle(job, outcome, log, failed_tasks, progress)
        finally:
            pool.stop([handle for _job, handle, *_ in running.values()])
    return done


# ----------------------------------------------------------------------------------------------
# the entry point and the flags


BACKENDS = ("local", "ray")
RAY_INSTALL = 'pip install -e ".[ray]"'


def _import_ray():
    """The ``ray`` module, or an ImportError that says what to install."""
    try:
        import ray
    except ImportError as err:
        raise ImportError(f"--backend ray needs Ray, which is not installed here: {RAY_INSTALL}") from err
    return ray


def _probe(address: str, timeout: float = 5.0) -> None:
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


def add_backend_flags(parser) -> None:
    """Add ``--backend {local,ray}`` and ``--ray-address ADDR`` to a sweep's ``parser``; check
    them with ``check_backend`` and pass ``args.backend``, ``args.ray_address`` to ``train_jobs``."""
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="where the runs train: local = in this process (--jobs 1) or in --jobs N worker "
                             "processes here; ray = one Ray task per run with cores // --jobs threads, as many at "
                             f"once as Ray has CPUs (needs {RAY_INSTALL}); see docs/sweeps.md")
    parser.add_argument("--ray-address", dest="ray_address", default=None, metavar="ADDR",
                        help="with --backend ray: the Ray cluster to join (its head's address, e.g. 10.0.0.1:6379, "
                             "or auto); default: start a local Ray with this machine's cores. --out must be on "
                             "storage every node sees at the same path")


def check_backend(parser, args) -> None:
    """Bad backend flags exit with one ``error:`` line (``parser.error``, code 2) naming the fix,
    among them ``--backend ray`` without Ray installed."""
    if args.ray_address is not None and args.backend != "ray":
        parser.error(f"--ray-address {args.ray_address}: only used with --backend ray; add --backend ray or drop it")
    if args.backend == "ray":
        try:
            _import_ray()
            if args.ray_address is not None:
                _probe(args.ray_address)
        except (ImportError, ConnectionError) as err:
            parser.error(str(err))


def train_jobs(jobs: list[dict], n_jobs: int, log_dir: Path, backend: str = "local",
               ray_address: str | None = None) -> tuple[dict, dict]:
    """Train ``jobs``; ``({key: run folder or exception}, seconds)``, key ``row/label/seed<seed>``.

    ``backend="local"``: here (``n_jobs`` 1) or in ``n_jobs`` worker processes with ``cores //
    n_jobs`` threads each; ``"ray"``: one Ray task per run with as many threads (and CPUs asked
    of Ray), on the Ray at ``ray_address`` (None: start a local one with this machine's cores,
    or use one already initialized). A run that fails maps to a ``RunFailed``, one whose task
    cannot run here to that task's FileNotFoundError / ImportError; the others train regardless.
    Logs go to ``log_dir``. ``seconds`` holds the training wall time, the backend, jobs, threads
    per job and each trained run's data / train / wall seconds.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend {backend!r}: choose one of {', '.join(BACKENDS)}")
    if ray_address is not None and backend != "ray":
        raise ValueError(f"ray_address {ray_address!r} is only used with backend='ray'; pass that or drop it")
    if n_jobs < 1:
        raise ValueError(f"n_jobs {n_jobs}: must be at least 1 (1 = train in this process)")
    in_process = backend == "local" and n_jobs == 1
    threads = torch.get_num_threads() if in_process else max(1, _cores() // n_jobs)
    tic, runs = time.perf_counter(), {}
    if jobs:
        pool = None if in_process else (_LocalPool(n_jobs, threads) if backend == "local"
                                        else _RayPool(threads, ray_address))
        progress = _Progress(sum(job["total"] for job in jobs))
        try:
            runs = (_train_in_process(jobs, progress, log_dir) if pool is None
                    else _train_in_workers(jobs, pool, progress, log_dir))
        finally:
            progress.close()
            if pool is not None:
                pool.close()
    seconds = {"training": time.perf_counter() - tic, "backend": backend, "jobs": n_jobs,
               "threads_per_job": threads, "runs": {}}
    for job in jobs:
        key = _run_key(job)
        if isinstance(runs.get(key), Path):
            m = _metrics(runs[key])
            seconds["runs"][key] = {"data": m.get("data_seconds"), "train": m.get("train_seconds"),
                                    "wall": job.get("wall")}
    return runs, seconds


def failures(runs: dict) -> list[RunFailed]:
    """The runs of a ``train_jobs`` result that failed (not those whose task cannot run here)."""
    return [err for err in runs.values() if isinstance(err, RunFailed)]


def exit_if_failed(runs: dict) -> None:
    """End the command with code 1 and the list of failed runs, if any (call it after writing
    what did train, so a rerun of the same command trains only what is missing)."""
    failed = failures(runs)
    if failed:
        print(f"{len(failed)} run{'s' if len(failed) > 1 else ''} failed; rerunning the same command trains only "
              "what is missing:\n" + "\n".join(f"  {err}" for err in failed), file=sys.stderr, flush=True)
        raise SystemExit(1)
