"""No library or analysis call leaves the caller's torch thread count or global random state changed: the
public entry points are called at an unusual thread count after a fixed seed, and both must be as they
were after; no code of ``hnn/`` or ``analysis/`` sets the thread count outside ``hnn.threads.torch_threads``
but a process pool's worker initializer (whose process is the worker's own)."""
import ast
import random
import re
from pathlib import Path

import numpy as np
import pytest
import torch

import hnn
from hnn.sweeps import group_runs, sweep

REPO = Path(__file__).resolve().parent.parent
# the functions that may set torch's thread count for good: a pool's worker initializers (the worker process
# is theirs), each passed only as ``initializer=`` (checked below)
INITIALIZERS = {("analysis/commands.py", "_worker_start"), ("analysis/chains/peer_measure.py", "one_thread")}


def _thread_setters() -> set[tuple[str, str]]:
    """``(file, enclosing function)`` of every ``*.set_num_threads(...)`` call in hnn/ and analysis/."""
    found = set()
    for path in [*REPO.glob("hnn/**/*.py"), *REPO.glob("analysis/**/*.py")]:
        tree = ast.parse(path.read_text(), str(path))
        for func in [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]:
            for node in ast.walk(func):
                if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "set_num_threads":
                    found.add((path.relative_to(REPO).as_posix(), func.name))
        # a call outside any function (at import) is one too
        inside = {id(node) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                  for node in ast.walk(f)}
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "set_num_threads"
                    and id(node) not in inside):
                found.add((path.relative_to(REPO).as_posix(), "<module>"))
    return found


def test_only_torch_threads_and_worker_initializers_set_the_thread_count():
    setters = _thread_setters()
    assert setters - INITIALIZERS == {("hnn/threads.py", "torch_threads")}, sorted(setters)
    for file, name in INITIALIZERS:
        uses = [m.group(0) for path in REPO.glob("analysis/**/*.py")
                for m in re.finditer(rf"[\w=]*\b{name}\b\(?", path.read_text())]
        # defined once, imported by name, and otherwise only handed to a pool as its initializer
        assert uses and all(u in (f"{name}(", name, f"initializer={name}") for u in uses), (file, uses)
        assert any(u == f"initializer={name}" for u in uses), (file, uses)


def _state():
    return (torch.get_num_threads(), torch.get_rng_state(), np.random.get_state(), random.getstate())


def _assert_same(before, after, what: str) -> None:
    assert after[0] == before[0], f"{what} left torch's thread count at {after[0]}, not the caller's {before[0]}"
    assert torch.equal(after[1], before[1]), f"{what} changed torch's global random state"
    assert after[2][0] == before[2][0] and np.array_equal(after[2][1], before[2][1]) and after[2][2:] == before[2][2:], \
        f"{what} changed numpy's global random state"
    assert after[3] == before[3], f"{what} changed Python's global random state"


@pytest.fixture
def unusual_threads():
    """Torch at a thread count no entry point picks for itself (3), its global generators seeded; the caller's
    count back after."""
    caller = torch.get_num_threads()
    torch.set_num_threads(3)
    torch.manual_seed(11)
    np.random.seed(11)
    random.seed(11)
    try:
        yield
    finally:
        torch.set_num_threads(caller)


def test_the_public_entry_points_leave_the_thread_count_and_the_random_state_as_they_were(tmp_path, unusual_threads):
    spring = hnn.load_task("spring")
    data = spring.get_dataset(seed=0)
    model = hnn.HNN(2, hnn.MLP(2, 8, 2))        # drawn before the state is read: a model's init is the caller's draw
    tiny = {"total_steps": 3, "hidden_dim": 8, "save_dir": str(tmp_path)}
    config = hnn.tasks.task_config("spring", tiny)
    protocol = hnn.EnergyProtocol("tiny", num_trials=5, num_points=10, rtol=1e-6)
    calls = {
        "hnn.train": lambda: hnn.train(model, data["x"], data["dxdt"], total_steps=3, progress=False),
        "hnn.train(threads=2)": lambda: hnn.train(model, data["x"], data["dxdt"], total_steps=3, progress=False,
                                                  threads=2),
        "hnn.prepare": lambda: hnn.prepare(config),
        "hnn.run_experiment": lambda: hnn.run_experiment(config),
        "hnn.load_run": lambda: hnn.load_run(hnn.runs.find_run(config)),
        "hnn.run_experiment(fit='swim')": lambda: hnn.run_experiment(
            hnn.tasks.task_config("spring", {**tiny, "fit": "swim", "seed": 1})),
        "hnn.fit_least_squares": lambda: hnn.fit_least_squares("hnn", data["x"], data["dxdt"], fit="swim", width=16,
                                                               seed=0),
        "hnn.rollout": lambda: hnn.rollout(model.time_derivative, torch.tensor([[1.0, 0.0]]), torch.linspace(0, 1, 5)),
        "hnn.evaluate_energy": lambda: hnn.evaluate_energy(spring, {"hnn": model}, protocol, progress=False),
        "hnn.tasks.run_task": lambda: hnn.tasks.run_task("spring", {**tiny, "seed": 2}, threads=2),
        "group_runs.train_group": lambda: group_runs.train_group(
            [hnn.tasks.task_config("spring", {**tiny, "seed": s}) for s in (3, 4)]),
        "sweep.train_jobs": lambda: sweep.train_jobs(
            [sweep.Job("spring/hnn/seed5", "spring", hnn.tasks.task_config("spring", {**tiny, "seed": 5}))], 1,
            tmp_path / "logs"),
    }
    for what, call in calls.items():
        before = _state()
        call()
        _assert_same(before, _state(), what)


def test_an_analysis_command_run_in_process_leaves_them_as_they_were(tmp_path, unusual_threads):
    from hnn_analysis.integrator_study import energy_drift

    before = _state()
    energy_drift.main(["--steps", "20", "--dt", "0.3", "--train-steps", "5", "--out", str(tmp_path)])
    _assert_same(before, _state(), "analysis/integrator_study/energy_drift.py's main")
