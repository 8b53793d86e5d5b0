"""hnn/sweeps/sweep.py: failed runs are reported and the others train (in this process, in worker
processes, on Ray), Ray gives the numbers of the local workers, and Ray stays an optional extra."""
import dataclasses
import importlib.util
import json
import os
import re
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
import torch

import hnn
from hnn_analysis import pages
from hnn import progress
from hnn.sweeps import backends, sweep
from hnn_analysis.paper import reproduce, study

needs_ray = pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                               reason=f"Ray is not installed: {backends.RAY_INSTALL}")
LOSSES = ("train_loss", "train_loss_se", "test_loss", "test_loss_se")


def _job(task: str, kind: str, runs_dir: Path, steps: int, **fields) -> sweep.Job:
    """A job as study.plan makes it (the scene study too)."""
    config = hnn.tasks.task_config(task, {"model": kind, "save_dir": str(runs_dir), "total_steps": steps, **fields})
    return sweep.Job(f"{task}/{kind}/seed0", task, config)


def test_the_longest_first_order_puts_runs_without_a_time_at_the_rate_of_those_with_one(tmp_path):
    """Runs of one task and steps, whose task cost cannot tell them apart, go by their expected seconds; one
    without them costs its task's rough cost at the median rate of the others (here 55 s); a group counts twice."""
    jobs = [dataclasses.replace(_job("spring", kind, tmp_path, 100), expected_seconds=seconds)
            for kind, seconds in (("baseline", 10.0), ("hnn", 100.0), ("mechanical", None))]
    order = sweep.longest_first([[job] for job in jobs])
    assert [unit[0].key for unit in order] == ["spring/hnn/seed0", "spring/mechanical/seed0", "spring/baseline/seed0"]
    pair = [jobs[0], dataclasses.replace(jobs[0], key="spring/baseline/seed1")]     # a group of 10 s runs: 20 s
    for alone, first in ((15.0, 2), (25.0, 1)):
        order = sweep.longest_first([pair, [dataclasses.replace(jobs[1], expected_seconds=alone)]])
        assert len(order[0]) == first, (alone, order)
    # none knows its time: the task's relative cost times the steps decides
    rough = [_job("spring", "hnn", tmp_path, 100), _job("spring", "baseline", tmp_path, 300)]
    assert [unit[0].key for unit in sweep.longest_first([[job] for job in rough])] == [
        "spring/baseline/seed0", "spring/hnn/seed0"]


@pytest.mark.parametrize("backend, n_jobs", [
    ("local", 1),
    ("local", 2),
    pytest.param("ray", 2, marks=needs_ray),
])
def test_a_run_that_raises_is_reported_and_the_others_train(backend, n_jobs, tmp_path, capsys):
    """The failing run (a nonlinearity that its check refuses) goes first (longest); the others
    train regardless, and the failure is reported by name with its traceback in a log."""
    runs_dir = tmp_path / "runs"
    bad = _job("spring", "baseline", runs_dir, 10 ** 4, nonlinearity="sideways")     # refused inside the run
    good = [_job("spring", "hnn", runs_dir, 20), _job("pend", "hnn", runs_dir, 20)]
    finished = []      # on_done sees each run as it finishes, its folder saved or its failure
    runs, seconds = sweep.train_jobs([bad] + good, n_jobs, tmp_path / "logs", backend=backend,
                                     on_done=lambda job, outcome: finished.append(
                                         (job.key, outcome, isinstance(outcome, Path) and outcome.is_dir())))
    assert sorted(finished, key=lambda f: f[0]) == sorted(((key, run, isinstance(run, Path)) for key, run in runs.items()),
                                                          key=lambda f: f[0])
    failed = runs["spring/baseline/seed0"]
    assert isinstance(failed, sweep.RunFailed) and "sideways" in failed.message and not failed.diverged
    assert "hnn/cli.py" in failed.log.read_text() and "sideways" in failed.log.read_text()   # where it raised
    for job in good:
        run = runs[job.key]
        assert isinstance(run, Path) and (run / hnn.runs.COMPLETE).is_file(), run
        assert json.loads((run / "args.json").read_text())["total_steps"] == 20
    assert sweep.failures(runs) == [failed]
    assert seconds["backend"] == backend and set(seconds["runs"]) == {"spring/hnn/seed0", "pend/hnn/seed0"}

    with pytest.raises(SystemExit) as info:
        sweep.exit_if_failed(runs)
    err = capsys.readouterr().err
    assert info.value.code == 1 and "1 run failed" in err and "spring/baseline/seed0: ValueError" in err
    sweep.exit_if_failed({key: run for key, run in runs.items() if run is not failed})   # no failure: returns


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_a_model_that_diverges_is_marked_so(n_jobs, tmp_path):
    """A run whose model fails (an hnn.DivergenceError: here a fresh black-box L on one bob whose d2L/dqdot2 is
    singular along its first snippets, as in the peers' table) is a failure its config repeats: marked
    ``diverged`` so a study can report it as a result, in this process or across a worker's pickling."""
    job = _job("chain", "lagrangian", tmp_path / "runs", 2, bobs=1, n_train=4, n_test=2, hidden_dim=8,
               nonlinearity="softplus", init="lnn")
    runs, _ = sweep.train_jobs([job], n_jobs, tmp_path / "logs")
    failed = runs[job.key]
    assert isinstance(failed, sweep.RunFailed) and failed.diverged, failed
    # the training loop says where the model failed: in a step or in the test batch after it. Which numerical
    # failure it meets first is round-off's choice (d2L/dqdot2 ~ 0, a 1 x 1 matrix: no finite qddot, a
    # SingularLagrangianError, or a huge finite one whose RK4 snippet diverges, a DivergenceError: tests/test_peers.py),
    # so the failure is asserted by its class, a DivergenceError, and where
    numerical, todo = set(), [hnn.DivergenceError]
    while todo:
        numerical.add(todo[-1].__name__)
        todo += todo.pop().__subclasses__()
    found = re.match(r"(\w+): at (the test batch after )?training step [0-2] of 2: ", failed.message)
    assert found and found[1] in numerical, failed.message


def test_a_sweep_job_parses_no_argv(tmp_path, monkeypatch):
    """Planning, reuse and training a sweep's runs go from config to folder: no parser is built."""
    def refuse(*args, **kwargs):
        raise AssertionError("a sweep job parsed argv")

    monkeypatch.setattr(hnn.cli, "make_parser", refuse)
    rows = study.table_rows(["spring"], quick=True)
    jobs = study.plan(rows, [0], tmp_path / "runs", 3)
    runs, todo = sweep.reuse(jobs)
    assert runs == {} and len(todo) == 2
    trained, _ = sweep.train_jobs(todo, 1, tmp_path / "logs")
    assert all(isinstance(run, Path) for run in trained.values())
    again, todo = sweep.reuse(jobs)
    assert again == trained and todo == []


def test_a_run_that_does_not_load_is_named_and_trained_again(tmp_path, capsys):
    jobs = [_job("spring", "hnn", tmp_path, 3)]
    trained, _ = sweep.train_jobs(jobs, 1, tmp_path / "logs")
    folder = trained["spring/hnn/seed0"]
    (folder / "model.tar").write_bytes(b"corrupt")
    runs, todo = sweep.reuse(jobs)
    out = capsys.readouterr().out
    assert runs == {} and todo == jobs
    assert f"spring/hnn/seed0: {folder / 'model.tar'} does not load" in out and "training it again" in out
    again, _ = sweep.train_jobs(todo, 1, tmp_path / "logs")
    assert again["spring/hnn/seed0"] == folder and hnn.load_run(folder)[1]["total_steps"] == 3


def test_reproduce_reports_a_failed_row_writes_the_rest_and_exits_1(tmp_path, monkeypatch, capsys):
    task = hnn.load_task("spring", "task")
    variant = {"broken": ({"nonlinearity": "sideways"}, "cannot build, for the test")}
    monkeypatch.setattr(task, "TASK", dataclasses.replace(task.TASK, variants=variant))
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as info:
        reproduce.main(["--quick", "--steps", "3", "--tasks", "spring", "--no-figures", "--out", str(out)])
    captured = capsys.readouterr()
    assert info.value.code == 1
    assert "2 runs failed" in captured.err and "spring-broken/hnn/seed0: ValueError" in captured.err
    saved = json.loads((out / "results.json").read_text())
    assert set(saved["tasks"]["spring"]) >= {"baseline", "hnn"}          # the rows that trained are in the tables
    assert (out / "tables.md").is_file()
    # the rerun trains only what is missing: the spring runs are reused
    with pytest.raises(SystemExit):
        reproduce.main(["--quick", "--steps", "3", "--tasks", "spring", "--no-figures", "--out", str(out)])
    said = [line for line in capsys.readouterr().out.splitlines() if line.startswith("reproduce: ") and " reused" in line]
    assert said == ["reproduce: 2 runs reused, 2 to train: spring-broken/baseline/seed0, spring-broken/hnn/seed0"]


def test_without_ray_the_ray_backend_says_what_to_install(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)        # import ray now raises ImportError
    with pytest.raises(SystemExit) as info:
        reproduce.main(["--quick", "--tasks", "spring", "--backend", "ray", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert info.value.code == 2
    assert err[-1] == 'error: --backend ray needs Ray, which is not installed here: pip install -e ".[ray]"'
    assert not (tmp_path / "runs").exists()                           # it stopped before training anything
    with pytest.raises(ImportError, match=r'pip install -e "\.\[ray\]"'):
        sweep.train_jobs([_job("spring", "hnn", tmp_path, 1)], 1, tmp_path / "logs", backend="ray")


@pytest.mark.parametrize("argv, match", [
    (["--ray-address", "10.0.0.1:6379"], "--ray-address 10.0.0.1:6379: only used with --backend ray"),
    (["--backend", "dask"], "invalid choice: 'dask'"),
])
def test_bad_backend_flags_exit_with_one_error_line(argv, match, capsys):
    with pytest.raises(SystemExit) as info:
        reproduce.main(["--quick", "--tasks", "spring"] + argv)
    err = capsys.readouterr().err
    assert info.value.code == 2 and match in err.splitlines()[-1]


@needs_ray
def test_a_ray_address_where_nothing_answers_exits_at_once(capsys):
    with pytest.raises(SystemExit) as info:
        reproduce.main(["--quick", "--tasks", "spring", "--backend", "ray", "--ray-address", "127.0.0.1:1"])
    last = capsys.readouterr().err.splitlines()[-1]
    assert info.value.code == 2 and last.startswith("error: --ray-address 127.0.0.1:1: nothing answers there")
    assert "ray start --head" in last


class _Pipe:
    """A stdout that is not a terminal, as when a command's output goes to a file: what a reader
    following it sees is what was flushed, kept as one snapshot per flush."""

    def __init__(self):
        self.text, self.snapshots = "", []

    def write(self, s):
        self.text += s

    def flush(self):
        self.snapshots.append(self.text)

    def isatty(self):
        return False


def test_every_run_says_runs_done_of_runs_to_do_and_the_time_so_far_as_it_ends(tmp_path, monkeypatch):
    pipe = _Pipe()
    monkeypatch.setattr(sys, "stdout", pipe)
    monkeypatch.setattr(backends, "HEARTBEAT", -1.0)        # no terminal: a line on every step of a lone run
    jobs = [_job("spring", "hnn", tmp_path, 3), _job("pend", "hnn", tmp_path, 3)]
    runs, _ = sweep.train_jobs(jobs, 1, tmp_path / "logs", group="off")
    done = [line.strip() for line in pipe.text.splitlines() if " trained " in line]
    assert len(done) == 2 and all(isinstance(run, Path) for run in runs.values())
    assert re.match(r"\[1/2, \d+ s\] \S+/hnn/seed0 trained ", done[0]), done
    assert re.match(r"\[2/2, \d+ s\] \S+/hnn/seed0 trained ", done[1]), done
    # the sweep's time left at its steps per second so far, until its last run
    assert re.search(r"\(\d+\.\d s\); the sweep: about \d+ s left$", done[0]) and "the sweep" not in done[1], done
    # each line reached the reader when it was written, not when the sweep ended (tqdm's write does not flush)
    assert any(done[0] in snap and done[1] not in snap for snap in pipe.snapshots), pipe.snapshots
    # a lone run says its steps where no bar is drawn, with the runs done so far
    assert re.search(r"\[0/2, \d+ s\] \S+/hnn/seed0: step 2 of 4, about \d+ s left", pipe.text), pipe.text


def test_a_run_in_a_worker_says_its_step_where_its_output_is_a_log(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(backends, "HEARTBEAT", -1.0)        # a line on every step
    job = _job("spring", "hnn", tmp_path, 3)
    folder = backends.run_reported(job.task, job.fields(), job.key, 1)
    assert hnn.runs.find_run(job.config) == Path(folder)
    lines = [line.strip() for line in capsys.readouterr().out.splitlines() if ": step " in line]
    assert lines[0] == "spring/hnn/seed0: step 1 of 4" and re.fullmatch(r"spring/hnn/seed0: step 4 of 4, about 0 s "
                                                                         r"left", lines[-1]), lines


def test_a_long_run_says_how_long_it_has_left_at_its_own_rate():
    # first seen at step 3000 (a resumed run: the steps before were trained in another sitting), 100 s later
    # at step 3500: 5 steps a second, 4500 steps to go
    rate = progress.Rate(3000, now=1000.0)
    assert rate.left(8000) is None                                                   # no rate yet
    rate.add(3500, now=1100.0)
    assert progress.say_left(rate.left(8000)) == "about 15 min left"
    assert progress.say_left(rate.left(8000, now=1110.0)) == "about 15 min left"     # 10 s since: 890 s
    rate = progress.Rate(0, now=0.0)
    rate.add(4900, now=1100.0)
    assert progress.say_left(rate.left(5000)) == "about 22 s left"                   # 4900 steps in 1100 s
    rate = progress.Rate(0, now=0.0)
    rate.add(100, now=100.0)
    assert progress.say_left(rate.left(8000)) == "about 2.2 h left"                  # a long sweep, in hours


def test_the_time_left_follows_a_run_that_slows_down(monkeypatch):
    # 10 steps a second for 10 minutes, then 2 (another job took the core): the line's estimate is the
    # steps left at the recent rate, not at the mean since the start (which said "about 4 min left" for minutes)
    now = [0.0]
    monkeypatch.setattr(progress.time, "perf_counter", lambda: now[0])
    beat, step, total = progress.Heartbeat(30.0), 0, 20_000
    beat.due(step, total)
    lines = []
    for rate in [10] * 20 + [2] * 10:
        now[0] += 31
        step += 31 * rate
        lines.append(beat.due(step, total))
    assert all(lines)
    left = (total - step) / 2
    said = float(re.search(r"about (\d+) min left", lines[-1]).group(1)) * 60
    assert abs(said - left) <= 60, (lines[-1], left)
    # the mean since the start would have said less than half of it
    assert (total - step) * now[0] / step < left / 2


def test_progress_counts_and_times():
    progress = sweep.Progress(3)
    assert progress.tag() == "[0/3, 0 s]"
    progress.start -= 42.4           # as if started 42 s ago
    assert progress.advance() == "[1/3, 42 s]" and progress.advance(2) == "[3/3, 42 s]"


def test_train_jobs_checks_its_arguments(tmp_path):
    with pytest.raises(ValueError, match="backend 'dask': choose one of local, ray"):
        sweep.train_jobs([], 1, tmp_path, backend="dask")
    with pytest.raises(ValueError, match="only used with backend='ray'"):
        sweep.train_jobs([], 1, tmp_path, ray_address="auto")
    with pytest.raises(ValueError, match="n_jobs 0: must be at least 1"):
        sweep.train_jobs([], 0, tmp_path)


def test_only_the_sweeps_backends_import_ray():
    root = hnn.tasks.repo_root()
    sources = [p for folder in ["hnn", "analysis", *[d.name for d in root.glob("experiment-*")]]
               for p in (root / folder).rglob("*.py")]
    importing = sorted(p.relative_to(root).as_posix() for p in sources
                       if any(line.strip().startswith(("import ray", "from ray")) for line in p.read_text().splitlines()))
    # Ray is an optional extra: the sweep's backend and the benchmark that measures that backend import it,
    # each inside a function that names the extra when it is missing; nothing else may.
    assert importing == ["analysis/benchmarks/ray_overhead.py", "analysis/benchmarks/ray_runs.py", "hnn/sweeps/backends.py"]


def test_the_stage_table_says_what_ran_the_runs():
    results = {"seconds": {"tasks": {"spring": {"data": 0.1, "train": {"hnn": 1.0}, "evaluate": 1.0, "figures": 0.0}},
                           "training": 2.0, "evaluation": 1.0, "total": 3.0, "jobs": 2, "threads_per_job": 1}}
    assert "2 worker processes of 1 threads" in "\n".join(pages.stage_table(results))
    results["seconds"]["backend"] = "ray"
    assert "Ray tasks of 1 thread each" in "\n".join(pages.stage_table(results))


@needs_ray
def test_ray_gives_the_numbers_of_the_local_backend(tmp_path):
    """A two-task quick sweep on a local Ray (this machine's cores; 2 here and in CI) against
    --backend local, both at one thread per process (Ray: --jobs = the cores; local: this process
    set to one thread, which test_reproduce shows the local workers match): the same
    floating-point operations, so every loss and energy number agrees exactly."""
    common = ["--quick", "--steps", "50", "--tasks", "spring", "pend", "--no-figures"]
    on_ray = reproduce.main(common + ["--jobs", str(max(2, sweep.cores())), "--backend", "ray",
                                      "--out", str(tmp_path / "ray")])
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        local = reproduce.main(common + ["--out", str(tmp_path / "local")])
    finally:
        torch.set_num_threads(threads)
    assert on_ray["seconds"]["backend"] == "ray" and on_ray["seconds"]["threads_per_job"] == 1
    assert local["seconds"]["threads_per_job"] == 1
    folders = sorted(p.name for p in (tmp_path / "ray" / "runs").iterdir() if p.is_dir())
    assert [name.rsplit("-", 1)[0] for name in folders] == ["pend-baseline-seed0", "pend-hnn-seed0",
                                                            "spring-baseline-seed0", "spring-hnn-seed0"]
    for name in folders:
        ray_metrics, local_metrics = (json.loads((tmp_path / side / "runs" / name / "metrics.json").read_text())
                                      for side in ("ray", "local"))
        assert {k: ray_metrics[k] for k in LOSSES} == {k: local_metrics[k] for k in LOSSES}, name
    for task in ("spring", "pend"):
        for kind in ("baseline", "hnn"):
            for key in ("train_loss", "test_loss", "energy_mse_paper", "energy_mse_corrected"):
                assert on_ray["tasks"][task][kind][key] == local["tasks"][task][kind][key], (task, kind, key)
    # a local rerun on the Ray output reuses every run: the same configs, whatever trained them
    again = reproduce.main(common + ["--out", str(tmp_path / "ray")])
    assert again["seconds"]["runs"] == {}


def _free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _ray_start(args: list[str], env: dict, log: Path) -> subprocess.Popen:
    """``ray start ... --block``: a node that stops (its raylet and workers) when this process gets SIGTERM."""
    return subprocess.Popen(["ray", "start", "--num-cpus=1", "--disable-usage-stats", "--block", *args], env=env,
                            stdout=log.open("w"), stderr=subprocess.STDOUT)


def _wait_for_nodes(address: str, expect: int, procs: list, timeout: float = 180.0) -> None:
    import ray
    host, port = address.rsplit(":", 1)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert all(p.poll() is None for p in procs), "a ray start process ended (its log is in tmp_path)"
        try:
            socket.create_connection((host, int(port)), timeout=2).close()
        except OSError:
            time.sleep(1)
            continue
        ray.init(address=address, logging_level="ERROR", log_to_driver=False)
        try:
            if sum(node["Alive"] for node in ray.nodes()) >= expect:
                return
        finally:
            ray.shutdown()
        time.sleep(2)
    raise TimeoutError(f"the Ray cluster at {address} did not reach {expect} nodes in {timeout} s")


@pytest.mark.slow
@needs_ray
def test_a_two_node_cluster_with_token_auth_loses_a_node_mid_sweep_and_a_rerun_completes(tmp_path, monkeypatch, capsys):
    """docs/sweeps.md's cluster recipe on this machine: a head and a second node (two raylets,
    token authentication on), a sweep with --ray-address, the second node stopped once the
    first run finishes. Its runs are retried on the head or reported by name; the others
    finish; a rerun trains only what is missing."""
    port, *node_ports = _free_ports(8)
    token, address = secrets.token_hex(16), f"127.0.0.1:{port}"
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    monkeypatch.setenv("RAY_AUTH_TOKEN", token)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(hnn.tasks.repo_root()),
                                                                     os.environ.get("PYTHONPATH")]))}
    # Ray's unix sockets live under --temp-dir, whose path must stay short (107 characters at most)
    temp = tempfile.mkdtemp(prefix="ray-", dir="/tmp")
    head = _ray_start(["--head", f"--port={port}", "--include-dashboard=false", f"--temp-dir={temp}"],
                      env, tmp_path / "head.log")
    node = None
    try:
        _wait_for_nodes(address, 1, [head])
        a, b, c, d, e, f, g = node_ports
        node = _ray_start([f"--address={address}", f"--node-manager-port={a}", f"--object-manager-port={b}",
                           f"--dashboard-agent-listen-port={c}", f"--dashboard-agent-grpc-port={d}",
                           f"--metrics-export-port={e}", f"--runtime-env-agent-port={f}",
                           f"--min-worker-port={g}", f"--max-worker-port={g + 50}"], env, tmp_path / "node.log")
        _wait_for_nodes(address, 2, [head, node])
        out = tmp_path / "out"

        def stop_the_second_node_after_the_first_run():
            deadline = time.monotonic() + 600
            while time.monotonic() < deadline and not list((out / "runs").glob("*/complete.json")):
                time.sleep(0.2)
            node.terminate()

        killer = threading.Thread(target=stop_the_second_node_after_the_first_run, daemon=True)
        killer.start()
        argv = ["--quick", "--steps", "1500", "--tasks", "spring", "pend", "--no-figures", "--out", str(out),
                "--backend", "ray", "--ray-address", address, "--jobs", str(sweep.cores())]
        failed = []
        try:
            reproduce.main(argv)
        except SystemExit as exit:
            assert exit.code == 1
            failed = [line.split(":")[0].strip() for line in capsys.readouterr().err.splitlines()
                      if line.startswith("  ") and "seed0:" in line]
            assert failed, "exit 1 without naming the failed runs"
        killer.join(timeout=60)
        assert node.wait(timeout=60) is not None                # the second node is gone
        trained = {p.parent.name for p in (out / "runs").glob("*/complete.json")}
        assert len(trained) + len(failed) == 4, (trained, failed)
        again = reproduce.main(argv)                             # on the head alone: only what is missing
        assert len(again["seconds"]["runs"]) == len(failed) and set(again["tasks"]) == {"spring", "pend"}
        assert len({p.parent.name for p in (out / "runs").glob("*/complete.json")}) == 4
    finally:
        for proc in (node, head):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=60)
        shutil.rmtree(temp, ignore_errors=True)


@pytest.mark.parametrize("backend, n_jobs", [("local", 1), ("local", 2), pytest.param("ray", 2, marks=needs_ray)])
def test_grouped_sweeps_save_the_runs_of_lone_ones(backend, n_jobs, tmp_path):
    """--group auto trains the narrow runs of one task and kind as one group (in this process or
    as one worker's unit) and a wide one alone; every run's numbers are its lone run's to the
    grouped training's tolerance (tests/test_grouped.py: measured 1e-6, 1e-4 allowed)."""
    def jobs(folder):
        cells = [(16, seed, fraction) for seed in (0, 1) for fraction in (0.5, 1.0)] + [(200, 0, 1.0)]
        return [sweep.Job(f"spring/hnn/w{w}f{f}/seed{s}", "spring",
                          hnn.tasks.task_config("spring", {"hidden_dim": w, "seed": s, "train_fraction": f,
                                                           "total_steps": 50, "save_dir": str(folder)}))
                for w, s, f in cells]
    units = sweep.plan_units(jobs(tmp_path), "auto")
    assert sorted(len(unit) for unit in units) == [1, 4]
    assert [len(unit) for unit in sweep.plan_units(jobs(tmp_path), "off")] == [1] * 5
    grouped, seconds = sweep.train_jobs(jobs(tmp_path / "grouped"), n_jobs, tmp_path / "logs", backend, group="auto")
    alone, _ = sweep.train_jobs(jobs(tmp_path / "alone"), 1, tmp_path / "logs", group="off")
    assert seconds["group"] == "auto" and set(grouped) == set(alone)
    for key, folder in grouped.items():
        assert isinstance(folder, Path) and folder.name == alone[key].name, key
        mine, theirs = (json.loads((f / "metrics.json").read_text()) for f in (folder, alone[key]))
        assert mine["history"].get("group_size", 1) == (1 if "w200" in key else 4)
        for name in LOSSES:
            assert mine[name] == pytest.approx(theirs[name], rel=1e-4), (key, name)


def test_the_ray_overhead_runs_alternate_and_compare_every_number_but_the_times():
    from hnn_analysis.benchmarks import ray_runs
    assert ray_runs.order(3) == ["local", "ray", "ray", "local", "local", "ray"]
    a = {"meta": {"commit": "x"}, "seconds": {"total": 1.0},
         "tasks": {"spring": {"hnn": {"energy": [1.0, float("nan")], "loss": 0.5, "ok": True, "train_seconds": 3.0}}}}
    b = {"meta": {"commit": "y"}, "seconds": {"total": 9.0},
         "tasks": {"spring": {"hnn": {"energy": [1.0, float("nan")], "loss": 0.5 * (1 + 1e-12), "ok": True}},
                   "pend": {"hnn": {"loss": 2.0}}}}
    got = ray_runs.compare(a, b)
    # times, provenance and booleans are not results; NaN on both sides counts as equal
    assert (got["numbers"], got["equal"], got["only_one_side"]) == (3, 2, 1)
    assert got["worst_relative_difference"] == pytest.approx(1e-12, rel=1e-3)


def test_a_worker_records_its_runs_divergence_as_it_fails_before_any_sweep_reads_it(tmp_path):
    # a sweep's parent reads the outcomes one by one and calls on_done between them (the peers' table measures
    # a run there, for up to half an hour): a run that failed meanwhile, its parent stopped before reading it,
    # had no record and trained again in the next sitting. The worker's own call writes it as the run fails
    bad = _job("spring", "hnn", tmp_path, 3, learn_rate=1e30)
    with pytest.raises(hnn.DivergenceError):
        hnn.tasks.run_task("spring", bad.fields())
    record = hnn.runs.diverged_record(bad.config)
    assert record.parent == tmp_path and json.loads(record.read_text())["message"].startswith("DivergenceError: ")
    found, todo = sweep.reuse([bad], diverged=True)
    assert todo == [] and found[bad.key].diverged


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_a_groups_model_that_fails_in_training_is_recorded_as_a_lone_runs_failure_is(n_jobs, tmp_path):
    # a group's model whose loss is no longer finite fails as a lone run does (hnn.trainers.group_loop.GroupedRunFailed
    # is a DivergenceError): marked diverged in the sweep, recorded by the worker as it fails, reused as such
    bad = [sweep.Job(f"spring/hnn/seed{s}", "spring", hnn.tasks.task_config(
        "spring", {"model": "hnn", "seed": s, "save_dir": str(tmp_path / "runs"), "total_steps": 3,
                   "hidden_dim": 16, "learn_rate": 1e30})) for s in (0, 1)]
    assert len(sweep.plan_units(bad, "all")) == 1
    outcomes = hnn.sweeps.group_runs.run_group_task("spring", [job.fields() for job in bad])
    assert all(o["diverged"] and "not finite" in o["error"] for o in outcomes), outcomes
    for job in bad:
        assert json.loads(hnn.runs.diverged_record(job.config).read_text())["message"].startswith("GroupedRunFailed: ")
        hnn.runs.diverged_record(job.config).unlink()
    done, _ = sweep.train_jobs(bad, n_jobs, tmp_path / "logs", group="all")
    assert all(isinstance(done[job.key], sweep.RunFailed) and done[job.key].diverged for job in bad), done
    found, todo = sweep.reuse(bad, diverged=True)
    assert todo == [] and all(found[job.key].message == done[job.key].message for job in bad)


def test_a_run_that_failed_in_training_is_recorded_and_a_table_reuses_its_failure(tmp_path, capsys):
    # a rate of 1e30: the loss is no longer finite after the first step, an hnn.DivergenceError (a result of the
    # config, which a rerun repeats), recorded beside the runs
    bad = _job("spring", "hnn", tmp_path, 3, learn_rate=1e30)
    done, _ = sweep.train_jobs([bad], 1, tmp_path / "logs")
    failed = done[bad.key]
    assert isinstance(failed, sweep.RunFailed) and failed.diverged
    record = sweep.diverged_record(bad.config)
    assert record.parent == tmp_path and json.loads(record.read_text())["message"] == failed.message
    # a table that reports such a failure as its cell takes it back without training; the others train it
    found, todo = sweep.reuse([bad], diverged=True)
    assert todo == [] and found[bad.key].diverged and found[bad.key].message == failed.message
    assert "failed in training in an earlier sitting" in capsys.readouterr().out
    assert sweep.reuse([bad])[1] == [bad]
    forced = dataclasses.replace(bad, config=dataclasses.replace(bad.config, force=True))
    assert sweep.reuse([forced], diverged=True)[1] == [forced]
    # a run that trains after all leaves no record of a failure
    good = _job("spring", "hnn", tmp_path, 3)
    sweep.diverged_record(good.config).write_text(json.dumps({"message": "HypotheticalError: from before"}))
    done, _ = sweep.train_jobs([good], 1, tmp_path / "logs")
    assert isinstance(done[good.key], Path) and not sweep.diverged_record(good.config).exists()
    # an unreadable record is named and the run trained again
    record.write_text("{not json")
    assert sweep.reuse([bad], diverged=True)[1] == [bad] and "cannot be read" in capsys.readouterr().out



@pytest.mark.parametrize("backend,jobs", [("local", 1), ("local", 2), pytest.param("ray", 1, marks=needs_ray)])
def test_map_cells_gives_each_cell_its_result_or_its_exception(backend, jobs):
    """The measuring's map: every cell's result by its index, whatever the backend; a cell that raises is its
    exception in its place, not the end of the map (math.sqrt: a function every worker imports by name)."""
    import math

    from hnn.sweeps.backends import map_cells
    got = dict(map_cells(math.sqrt, [9.0, -1.0, 25.0], jobs, backend))
    assert got[0] == 3.0 and got[2] == 5.0
    assert isinstance(got[1], ValueError) and "math domain error" in str(got[1])
    with pytest.raises(ValueError, match="backend 'dask': choose one of local, ray"):
        list(map_cells(math.sqrt, [1.0], 1, "dask"))
    with pytest.raises(ValueError, match="jobs=0"):
        list(map_cells(math.sqrt, [1.0], 0))
