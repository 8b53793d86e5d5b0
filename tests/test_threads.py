"""hnn.threads: a block's torch thread count, the caller's back however the block ends; hnn.train and
hnn.evaluate_energy on one thread unless told."""
import types

import pytest
import torch

import hnn
from hnn.threads import cores, torch_threads


def test_a_blocks_thread_count_is_its_own_and_the_callers_returns_even_on_an_error():
    caller = torch.get_num_threads()
    other = 2 if caller == 1 else 1
    with torch_threads(other):
        assert torch.get_num_threads() == other
        with torch_threads(None):                       # None: left as the block outside set it
            assert torch.get_num_threads() == other
    assert torch.get_num_threads() == caller
    with pytest.raises(KeyError), torch_threads(other):
        raise KeyError("a failure inside the block")
    assert torch.get_num_threads() == caller
    with pytest.raises(ValueError, match="at least 1"), torch_threads(0):
        pass
    assert torch.get_num_threads() == caller and cores() >= 1


def _spy_fit(model, seen: list, fail_at: int | None = None, **options):
    """``hnn.train`` of ``model`` on a tiny spring set with a loss that records the thread count of every step."""
    x = torch.randn(32, 2)
    dxdt = torch.cat([x[:, 1:], -x[:, :1]], 1)

    def loss(xb, yb):
        seen.append(torch.get_num_threads())
        if fail_at is not None and len(seen) == fail_at:
            raise ValueError("a failure inside the fit")
        return (model.time_derivative(xb) - yb).pow(2)
    return hnn.train(model, x, dxdt, total_steps=3, loss=loss, progress=False, **options)


def test_train_and_the_energy_protocol_run_on_one_thread_by_default_and_give_the_callers_count_back(spring):
    caller = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        model, seen = hnn.HNN(2, hnn.MLP(2, 8, 2)), []
        _spy_fit(model, seen)
        assert set(seen) == {1} and torch.get_num_threads() == 2      # the commands' one thread, the caller's after
        seen.clear()
        _spy_fit(model, seen, threads=2)
        assert set(seen) == {2} and torch.get_num_threads() == 2
        seen.clear()
        torch.set_num_threads(3)
        with pytest.raises(ValueError, match="a failure inside the fit"):
            _spy_fit(model, seen, fail_at=2)
        assert seen == [1, 1] and torch.get_num_threads() == 3        # restored however the fit ends
        seen.clear()
        _spy_fit(model, seen, threads=None)                           # None: the caller's count as it is
        assert set(seen) == {3}

        def field(x):
            seen.append(torch.get_num_threads())
            return spring.dynamics(x)
        seen.clear()
        protocol = hnn.EnergyProtocol("tiny", num_trials=5, num_points=10, rtol=1e-6)
        system = types.SimpleNamespace(dynamics=field, hamiltonian=spring.hamiltonian)
        hnn.evaluate_energy(system, {"hnn": model}, protocol, progress=False)
        assert set(seen) == {1} and torch.get_num_threads() == 3
    finally:
        torch.set_num_threads(caller)


def test_a_fit_says_how_far_it_is_where_no_bar_is_drawn_and_nothing_when_told(capsys, monkeypatch):
    monkeypatch.setattr(hnn.progress, "LINE_EVERY", -1.0)        # a line at every step instead of every 10 s
    x = torch.randn(32, 2)
    dxdt = torch.cat([x[:, 1:], -x[:, :1]], 1)
    hnn.train(hnn.HNN(2, hnn.MLP(2, 8, 2)), x, dxdt, total_steps=3)     # stderr is no terminal here: lines
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("train: step 1 of 4, about ") and lines[-1].startswith("train: step 4 of 4, about "), lines
    hnn.train(hnn.HNN(2, hnn.MLP(2, 8, 2)), x, dxdt, total_steps=3, progress=False)
    assert capsys.readouterr().err == ""


def test_a_sweeps_lone_and_group_jobs_give_the_callers_thread_count_back(tmp_path):
    """``hnn.tasks.run_task`` and ``hnn.sweeps.group_runs.run_group_task`` run at the job's count and
    leave the caller's as it was: a library call changes no global setting."""
    from hnn.sweeps.group_runs import run_group_task
    from hnn.tasks import run_task

    caller = torch.get_num_threads()
    other = 2 if caller == 1 else 1
    values = dict(total_steps=2, save_dir=str(tmp_path), verbose=False)
    try:
        assert run_task("spring", values, threads=other)
        assert torch.get_num_threads() == caller
        outcomes = run_group_task("spring", [dict(values, seed=1), dict(values, seed=2)], threads=other)
        assert all("folder" in o for o in outcomes), outcomes
        assert torch.get_num_threads() == caller
    finally:
        torch.set_num_threads(caller)
