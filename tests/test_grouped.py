"""Models trained as one group agree with the same configs trained alone, a failing model is
reported by name without touching the others, and grouped runs save and load as any run."""
import copy
import json

import numpy as np
import pytest
import torch

import hnn
from hnn.sweeps.group_runs import closed_form_key
from hnn.trainers.closed_form import train_closed_form
from hnn.policy import training_subset

# Measured (spring, 300 and 2000 steps, 1 and 2 threads): final weights and per-step losses of a
# grouped model are within 1e-6 relative of its lone run's. They are not equal bit for bit because
# a batched product (bmm over the group) sums in another order than the lone run's mm, and Adam
# carries those last-bit differences forward; 1e-4 leaves room for other BLAS builds and still
# fails at once on any real difference (another minibatch, init or gradient moves the loss by >1%).
RTOL = 1e-4
STEPS = 300


def _spring_cells(widths, seeds, fractions):
    """``[(width, seed, fraction)]`` and each seed's spring dataset."""
    data = {seed: hnn.load_task("spring").get_dataset(seed=seed) for seed in seeds}
    return [(w, s, f) for w in widths for s in seeds for f in fractions], data


def _model(width: int, seed: int, kind: str = "hnn"):
    torch.manual_seed(seed)
    return hnn.kinds.model_from_args({"kind": kind, "input_dim": 2, "hidden_dim": width, "nonlinearity": "tanh",
                                          "field_type": "solenoidal"})


def _close(a, b) -> float:
    """Largest difference of ``a`` and ``b`` relative to ``b``'s largest magnitude."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def _lone(model, pair, test, seed, batch_size, input_noise=0.0):
    return hnn.train(model, *pair, *test, total_steps=STEPS, seed=seed, batch_size=batch_size, input_noise=input_noise)


@pytest.mark.parametrize("kind, batch_size, noise", [("hnn", None, 0.0), ("hnn", 100, 0.0), ("hnn", 100, 0.05),
                                                     ("baseline", None, 0.0), ("dissipative", None, 0.0),
                                                     ("separable", None, 0.0)])
def test_grouped_training_agrees_with_lone_runs(kind, batch_size, noise):
    cells, data = _spring_cells((16, 32), (0, 1), (0.25, 1.0))
    for width in (16, 32):              # a group is one width
        mine = [c for c in cells if c[0] == width]
        models = [_model(w, s, kind) for w, s, _ in mine]
        alone = [copy.deepcopy(m) for m in models]
        pairs = [training_subset(data[s]["x"], data[s]["dxdt"], f, s) for _, s, f in mine]
        tests = [(data[s]["test_x"], data[s]["test_dxdt"]) for _, s, _ in mine]
        stats, failures = train_closed_form(models, pairs, tests, seeds=[s for _, s, _ in mine], total_steps=STEPS,
                                            batch_size=batch_size, input_noise=noise)
        assert failures == {}
        for g, (_, seed, _) in enumerate(mine):
            lone = _lone(alone[g], pairs[g], tests[g], seed, batch_size, noise)
            assert _close(stats[g]["train_loss"], lone["train_loss"]) < RTOL, mine[g]
            assert _close(stats[g]["test_loss"], lone["test_loss"]) < RTOL, mine[g]
            assert stats[g]["test_steps"] == lone["test_steps"]
            for p, q in zip(models[g].parameters(), alone[g].parameters()):
                assert _close(p.detach(), q.detach()) < RTOL, mine[g]
        # the cells differ from each other far beyond the tolerance: the test can tell them apart
        flat = [torch.cat([p.detach().flatten() for p in m.parameters()]) for m in models]
        assert min(_close(a, b) for i, a in enumerate(flat) for b in flat[i + 1:]) > 100 * RTOL


def test_a_model_that_turns_nan_is_reported_and_the_others_finish_as_alone(capsys):
    cells, data = _spring_cells((16,), (0, 1, 2), (1.0,))
    models = [_model(w, s) for w, s, _ in cells]
    alone = [copy.deepcopy(m) for m in models]
    pairs = [(data[s]["x"], data[s]["dxdt"]) for _, s, _ in cells]
    tests = [(data[s]["test_x"], data[s]["test_dxdt"]) for _, s, _ in cells]

    def poison(step, weights):
        if step == 40:
            with torch.no_grad():
                weights[2][1, 0, 0] = float("nan")     # model 1's W2: its loss is NaN from step 41

    stats, failures = train_closed_form(models, pairs, tests, seeds=[s for _, s, _ in cells], total_steps=STEPS,
                                        names=["spring-a", "spring-b", "spring-c"], after_step=poison)
    assert list(failures) == [1] and stats[1] is None
    assert failures[1].name == "spring-b" and failures[1].step == 41
    assert "spring-b" in capsys.readouterr().out
    for g in (0, 2):
        lone = _lone(alone[g], pairs[g], tests[g], cells[g][1], None)
        assert np.isfinite(stats[g]["train_loss"]).all()
        assert _close(stats[g]["train_loss"], lone["train_loss"]) < RTOL
        for p, q in zip(models[g].parameters(), alone[g].parameters()):
            assert _close(p.detach(), q.detach()) < RTOL


def test_grouped_runs_save_as_ordinary_runs_that_load_and_evaluate(tmp_path):
    configs = [hnn.tasks.task_config("spring", {"seed": s, "train_fraction": f, "hidden_dim": 16, "total_steps": 100,
                                                "save_dir": str(tmp_path)}) for s in (0, 1) for f in (0.5, 1.0)]
    assert len({closed_form_key(c) for c in configs}) == 1
    folders = hnn.sweeps.group_runs.train_group(configs)
    assert [hnn.runs.find_run(c) for c in configs] == folders        # found by their configs, as lone runs are
    lone_dir = tmp_path / "lone"
    for config, folder in zip(configs, folders):
        model, args, metrics = hnn.load_run(folder)
        data = config.dataset()
        test_loss = hnn.derivative_mse(model, data["test_x"], data["test_dxdt"])[0]
        assert test_loss == pytest.approx(metrics["test_loss"], rel=1e-6)
        assert metrics["history"]["group_size"] == len(configs)
        assert args["kind"] == "hnn" and json.loads((folder / "args.json").read_text())["seed"] == config.seed
        traj = hnn.rollout(model.time_derivative, torch.as_tensor(data["test_x"][:2]), torch.linspace(0, 1, 11))
        assert torch.isfinite(traj).all()
        config.save_dir = str(lone_dir)
        lone_model = hnn.load_run(hnn.run_experiment(config))[0]
        for p, q in zip(model.parameters(), lone_model.parameters()):
            assert _close(p.detach(), q.detach()) < RTOL


def test_configs_that_cannot_group_say_so():
    config = hnn.tasks.task_config("spring", {"use_rk4": True})
    assert closed_form_key(config) is None          # the closed form's groups: not through an RK4 step
    assert hnn.sweeps.group_runs.unit_key(config)[0] == "vmap"
    pixels = hnn.tasks.task_config("pixels", {})
    assert hnn.sweeps.group_runs.unit_key(pixels) is None
    with pytest.raises(ValueError, match="one group"):
        hnn.sweeps.group_runs.train_group([pixels])
