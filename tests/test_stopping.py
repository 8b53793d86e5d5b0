"""A signal to a real sweep's process (two spawned workers, tiny spring runs): the runs not started
are cancelled, the workers stop, the finished runs stay whole, one line says so and the exit code
is 128 + the signal; a worker whose parent is killed outright stops by itself."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import hnn

REPO = hnn.tasks.repo_root()
RUNS = 8
SWEEP = f"""
import sys
from pathlib import Path
import hnn
from hnn.sweeps import sweep
out = Path(sys.argv[1])
jobs = [sweep.Job(f"spring/hnn/seed{{seed}}", "spring", hnn.tasks.task_config(
    "spring", {{"seed": seed, "hidden_dim": 8, "total_steps": 400, "save_dir": str(out)}})) for seed in range({RUNS})]
sweep.train_jobs(jobs, 2, out / "logs", group="off")
print("the sweep ran to its end")
"""


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (read from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not yet reaped, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _start_and_wait_for_a_finished_run(tmp_path: Path) -> tuple[subprocess.Popen, list[str]]:
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-c", SWEEP, str(tmp_path)], cwd=REPO, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    lines = []
    for line in proc.stdout:
        lines.append(line)
        if " trained " in line:
            return proc, lines
    proc.wait()
    pytest.fail("the sweep ended before any run finished:\n" + "".join(lines))


def _complete_runs(out: Path) -> list[Path]:
    return [run for run in out.glob("spring-hnn-*") if (run / hnn.runs.COMPLETE).is_file()]


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc")
# SIGINT takes the same path as SIGTERM (KeyboardInterrupt for Interrupted): slow, for ~15 s of start-up
@pytest.mark.parametrize("signum", [signal.SIGTERM, pytest.param(signal.SIGINT, marks=pytest.mark.slow)])
def test_a_signal_to_the_sweep_stops_it_keeps_the_finished_runs_and_says_so(signum, tmp_path):
    proc, lines = _start_and_wait_for_a_finished_run(tmp_path)
    workers = _children(proc.pid)
    assert workers, "the sweep should run in worker processes"
    os.kill(proc.pid, signum)
    rest, _ = proc.communicate(timeout=60)
    output = "".join(lines) + rest
    assert proc.returncode == 128 + signum, output
    said = [line for line in output.splitlines() if line.startswith("interrupted")]
    assert len(said) == 1 and signal.Signals(signum).name in said[0], output
    assert "Traceback" not in output and "the sweep ran to its end" not in output
    assert "leaked" not in output, output
    kept = _complete_runs(tmp_path)
    assert 1 <= len(kept) < RUNS and f"kept the {len(kept)} finished run" in said[0]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "a half-written folder was left"
    for run in kept:
        hnn.load_run(run)            # whole: it loads
    deadline = time.monotonic() + 20
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(_alive(pid) for pid in workers), "a worker outlived the sweep"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc")
def test_workers_stop_when_the_sweep_is_killed_outright(tmp_path):
    proc, _ = _start_and_wait_for_a_finished_run(tmp_path)
    workers = _children(proc.pid)
    assert workers
    proc.kill()
    proc.communicate(timeout=30)
    deadline = time.monotonic() + 20      # a worker looks for its parent every 0.5 s, then gives its run 10 s
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(_alive(pid) for pid in workers), "an orphaned worker trains on"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "a half-written folder was left"


def test_an_interrupt_counts_a_run_a_worker_finished_as_it_was_stopped(tmp_path, monkeypatch, capsys):
    """A worker can finish its run between the sweep's last result and its stop: the folder is whole on disk, so
    the interrupt's line counts it as kept and not among the runs that left no folder."""
    from types import SimpleNamespace

    import hnn.runs
    from hnn.sweeps.stopping import interruptible
    folder = tmp_path / "finished-as-stopped"
    folder.mkdir()
    jobs = [SimpleNamespace(key="a", config="A"), SimpleNamespace(key="b", config="B")]
    monkeypatch.setattr(hnn.runs, "find_run", lambda config: folder if config == "B" else None)
    runs = {}
    with pytest.raises(SystemExit):
        with interruptible(runs, jobs):
            raise KeyboardInterrupt
    assert runs == {"b": folder}
    assert "kept the 1 finished run; the 1 not finished" in capsys.readouterr().err
