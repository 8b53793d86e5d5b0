"""The training loop, the train.py scripts end to end, and saved runs."""
import json

import numpy as np
import pytest
import torch

import hnn


def test_train_fits_a_spring_and_reports_history(spring):
    d = spring.get_dataset(seed=0, noise_std=0.0)
    model = hnn.build_model(2, 32)
    stats = hnn.train(model, d["x"], d["dxdt"], d["test_x"], d["test_dxdt"], total_steps=300, learn_rate=1e-2,
                      print_every=100)
    assert len(stats["train_loss"]) == 301                      # total_steps + 1, as the original
    assert stats["test_steps"] == [0, 100, 200, 300]
    assert stats["train_loss"][-1] < 0.02 * stats["train_loss"][0]
    assert stats["test_loss"][-1] < 0.02 * stats["test_loss"][0]


def test_minibatches_are_seeded(spring):
    d = spring.get_dataset(seed=0)
    runs = []
    for _ in range(2):
        torch.manual_seed(0)
        model = hnn.build_model(2, 16)
        runs.append(hnn.train(model, d["x"], d["dxdt"], total_steps=20, batch_size=50, seed=3)["train_loss"])
    assert runs[0] == runs[1]


@pytest.mark.parametrize("before", [True, False])
def test_train_restores_the_callers_denormal_flushing(before):
    model = hnn.build_model(2, 8)
    x = np.random.RandomState(0).randn(20, 2).astype(np.float32)
    tiny = torch.finfo(torch.float32).tiny                       # the smallest normal float32
    if not torch.set_flush_denormal(before):
        pytest.skip("this CPU cannot flush denormals")
    try:
        hnn.train(model, x, x, total_steps=2)
        assert (torch.full((1,), tiny) / 2 == 0).item() == before    # half of it is denormal unless flushed
        assert hnn.trainers.loop.flushes_denormals() == before
    finally:
        torch.set_flush_denormal(False)


def test_bad_training_data_is_named():
    model = hnn.build_model(2, 8)
    x = np.zeros((10, 2), dtype=np.float32)
    bad = x.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"dxdt has 1 NaN/inf values \(first in row 4"):
        hnn.train(model, x, bad, total_steps=1)
    with pytest.raises(ValueError, match="x has 3 columns but the model expects input_dim=2"):
        hnn.train(model, np.zeros((10, 3)), np.zeros((10, 3)), total_steps=1)
    with pytest.raises(ValueError, match="x has 10 rows but dxdt has 9"):
        hnn.train(model, x, x[:9], total_steps=1)
    with pytest.raises(ValueError, match=r"shape \(rows, dim\)"):
        hnn.train(model, np.zeros(10), np.zeros(10), total_steps=1)


@pytest.mark.parametrize("task", ["spring", "pend"])
@pytest.mark.parametrize("extra", [[], ["--baseline"], ["--use_rk4"]])
def test_train_script_end_to_end(task, extra, tmp_path, capsys):
    trainer = hnn.load_task(task, "train")
    run = trainer.main(["--total_steps", "5", "--print_every", "2", "--verbose", "--save_dir", str(tmp_path)] + extra)
    out = capsys.readouterr().out
    assert "step 4, train_loss" in out and "Final train loss" in out and "Final test loss" in out
    label = "baseline" if "--baseline" in extra else "hnn-rk4" if "--use_rk4" in extra else "hnn"
    assert run.parent == tmp_path and run.name.startswith(f"{task}-{label}-seed0-")
    args = json.loads((run / "args.json").read_text())
    metrics = json.loads((run / "metrics.json").read_text())
    assert args["total_steps"] == 5 and args["weight_decay"] == 1e-4
    assert len(metrics["history"]["train_loss"]) == 6 and metrics["test_loss"] > 0
    model, saved_args, _ = hnn.load_run(run)                    # weights_only=True inside
    assert saved_args == args and model.baseline == ("--baseline" in extra)
    assert args["model"] == ("baseline" if "--baseline" in extra else "hnn") and "baseline" not in args
    assert not list(tmp_path.rglob("*.tmp"))                     # atomic writes leave nothing behind


def test_runs_are_reused_only_for_identical_args(tmp_path):
    trainer = hnn.load_task("spring", "train")
    argv = ["--total_steps", "2", "--save_dir", str(tmp_path)]
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv)) is None
    run = trainer.main(argv)
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv)) == run
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv + ["--verbose"])) == run        # display only
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv[:1] + ["3"] + argv[2:])) is None
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv + ["--learn_rate", "0.01"])) is None


def test_unreadable_checkpoint_says_what_to_do(tmp_path):
    (tmp_path / "model.tar").write_bytes(b"not a checkpoint")
    (tmp_path / "complete.json").write_text('{"files": ["model.tar"]}')
    with pytest.raises(RuntimeError, match="model.tar does not load.*delete the folder .* and retrain") as info:
        hnn.load_run(tmp_path)
    assert "weights_only" not in str(info.value)
    with pytest.raises(FileNotFoundError, match="train it first"):
        hnn.load_run(tmp_path / "missing")


def test_cosine_schedule_anneals_from_the_rate_to_zero():
    from hnn.trainers.loop import learning_rate
    assert learning_rate(3e-3, 0, 100, "cosine") == 3e-3
    assert learning_rate(3e-3, 50, 100, "cosine") == pytest.approx(1.5e-3, rel=1e-12)
    assert learning_rate(3e-3, 100, 100, "cosine") == pytest.approx(0.0, abs=1e-18)
    assert learning_rate(3e-3, 70, 100, "constant") == 3e-3
    with pytest.raises(ValueError, match="schedule='linear'"):
        learning_rate(1e-3, 0, 10, "linear")


@pytest.mark.parametrize("kind", ["adam", "adamw"])
def test_adam_and_adamw_decay_weights_as_their_definitions_say(kind):
    """A weight whose loss has no gradient, one step: Adam's decay enters the gradient, so the step is
    lr * g / |g| = lr; AdamW's is decoupled, w <- w (1 - lr wd), and the zero gradient moves nothing."""
    from hnn.trainers.loop import adam_optimizer
    w = torch.nn.Parameter(torch.tensor([2.0], dtype=torch.float64))
    optim = adam_optimizer(torch.nn.ParameterList([w]), learn_rate=0.1, weight_decay=0.5, kind=kind)
    (0.0 * w).sum().backward()
    optim.step()
    expected = 2.0 - 0.1 if kind == "adam" else 2.0 * (1 - 0.1 * 0.5)
    assert w.item() == pytest.approx(expected, rel=1e-6)       # rel: Adam's eps 1e-8 against |g| = 1


def test_schedule_and_clipping_change_training_and_bad_values_are_named(spring):
    d = spring.get_dataset(seed=0, noise_std=0.0)

    def fit(**options):
        torch.manual_seed(0)
        model = hnn.build_model(2, 16)
        return hnn.train(model, d["x"], d["dxdt"], total_steps=40, learn_rate=1e-2, **options)["train_loss"]

    plain = fit()
    assert fit(optimizer="adam", schedule="constant", clip_grad=0.0) == plain     # the defaults are the paper's
    assert fit(schedule="cosine")[1:] != plain[1:] and fit(schedule="cosine")[0] == plain[0]
    assert fit(clip_grad=1e-3)[1:] != plain[1:]
    with pytest.raises(ValueError, match="clip_grad"):
        fit(clip_grad=-1.0)
    with pytest.raises(ValueError, match="optimizer='sgd'"):
        fit(optimizer="sgd")


def test_configs_off_the_papers_optimizer_train_alone_not_in_a_group():
    config = hnn.tasks.task_config("spring", {"hidden_dim": 16})
    assert hnn.sweeps.group_runs.closed_form_key(config) is not None
    for change in ({"optimizer": "adamw"}, {"schedule": "cosine"}, {"clip_grad": 1.0}, {"derivative_loss": "l1"}):
        assert hnn.sweeps.group_runs.closed_form_key(hnn.tasks.task_config("spring", {"hidden_dim": 16, **change})) is None


def test_a_loss_that_turns_nan_stops_training_and_names_its_step(spring):
    d = spring.get_dataset(seed=0, noise_std=0.0)
    model = hnn.build_model(2, 16)
    with torch.no_grad():
        model.differentiable_model.linear3.weight.mul_(1e30)     # the loss overflows float32 at once
    with pytest.raises(hnn.DivergenceError, match="at step 0 of 10.*--clip_grad"):
        hnn.train(model, d["x"], d["dxdt"], total_steps=10)


def test_a_test_batch_that_diverges_before_the_end_is_recorded_and_one_at_the_end_fails_the_run(spring, capsys):
    """A test batch only watches training: one that runs off (a held-out snippet of an early field, say)
    is recorded with its step and training goes on; the last one is the trained model's, and fails the run."""
    d = spring.get_dataset(seed=0, noise_std=0.0)

    def diverging_at(bad_steps):
        tests = iter(range(10 ** 6))

        def loss(x, y):
            if not torch.is_grad_enabled() and next(tests) in bad_steps:    # the n-th test batch runs off
                raise hnn.DivergenceError("rk4 (dt=0.03): 1 trajectories diverged: #3 at t=0.12")
            return (model.time_derivative(x) - y).pow(2).sum(1)
        return loss

    torch.manual_seed(0)
    model = hnn.build_model(2, 16)
    stats = hnn.train(model, d["x"], d["dxdt"], d["test_x"], d["test_dxdt"], total_steps=40, learn_rate=1e-2,
                      print_every=10, loss=diverging_at({0, 2}), verbose=True)
    assert stats["test_steps"] == [10, 30, 40] and len(stats["test_loss"]) == 3 and len(stats["train_loss"]) == 41
    assert [entry["step"] for entry in stats["test_diverged"]] == [0, 20]
    assert stats["test_diverged"][0]["why"].startswith("at the test batch after training step 0 of 40: rk4")
    out, err = capsys.readouterr()
    assert err.count("warning: at the test batch after training step") == 1 and "training goes on" in err
    assert "step 0, train_loss" in out and "test batch diverged" in out
    torch.manual_seed(0)
    model = hnn.build_model(2, 16)
    with pytest.raises(hnn.DivergenceError, match="^at the test batch after training step 40 of 40: rk4"):
        hnn.train(model, d["x"], d["dxdt"], d["test_x"], d["test_dxdt"], total_steps=40, print_every=10,
                  loss=diverging_at({4}))


def test_data_far_from_unit_scale_warns_and_a_hamiltonian_rescaling_does_not(spring):
    """A spring in raw units (q in 1e2, p in 2.5e2, as a measured oscillator): at the default, units='auto',
    a plain model is refused with the fix; with units='off' it trains with a warning naming every part's size
    (dq/dt too, whose RMS of 0.028 under a heavy mass went unwarned while the largest column's was read);
    divided by the spreads (one degree of freedom: any pair of factors keeps Hamilton's equations) it does not."""
    import warnings
    d = spring.get_dataset(seed=0)
    raw_x, raw_dxdt = (torch.as_tensor(d[key]) * torch.tensor([100.0, 250.0]) for key in ("x", "dxdt"))
    model = hnn.HNN(2, hnn.MLP(2, 8, 2))
    with pytest.raises(ValueError, match=r"units='auto': x and dxdt are far from unit scale \(RMS q 45.*train "
                                         r"hnn.units.Rescaled\(model\) instead.*or pass units='off'"):
        hnn.train(model, raw_x, raw_dxdt, total_steps=0)
    with pytest.warns(UserWarning) as record:
        hnn.train(model, raw_x, raw_dxdt, total_steps=0, units="off")
    assert [str(w.message).split(" (")[0] for w in record] == ["x and dxdt are far from unit scale"]
    assert "Scale your states" in str(record[0].message) and "dp/dt 224" in str(record[0].message)
    heavy = torch.as_tensor(d["x"]) * torch.tensor([1.0, 28.0]), torch.as_tensor(d["dxdt"]) * torch.tensor([0.028, 1.0])
    with pytest.warns(UserWarning, match=r"RMS q 0.45\d, p 12.\d, dq/dt 0.025\d, dp/dt 0.89\d"):
        hnn.train(model, *heavy, total_steps=0, units="off")
    spread = raw_x.std(dim=0)                   # q by q's spread, p by p's; their derivatives alike
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hnn.train(model, raw_x / spread, raw_dxdt / spread, total_steps=0)


@pytest.mark.parametrize("derivative_loss, error", [("l2", lambda r: r.pow(2)), ("l1", lambda r: r.abs())])
def test_the_derivative_loss_is_the_error_it_names(spring, tmp_path, derivative_loss, error):
    """A run's first training loss (full batch, taken before the first step) is the mean squared or absolute
    error of its untrained model's dx/dt, computed here from the same seeded init; the reported train and
    test losses stay the squared error either way, so runs of both compare."""
    d = spring.get_dataset(seed=0)
    config = hnn.tasks.task_config("spring", {"hidden_dim": 8, "total_steps": 0, "derivative_loss": derivative_loss,
                                              "save_dir": str(tmp_path)})
    run = hnn.run_experiment(config)
    torch.manual_seed(0)
    untrained = hnn.kinds.model_from_args({"kind": "hnn", "input_dim": 2, "hidden_dim": 8})
    residual = torch.as_tensor(d["dxdt"], dtype=torch.float32) - untrained.time_derivative(
        torch.as_tensor(d["x"], dtype=torch.float32))
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["history"]["train_loss"][0] == pytest.approx(error(residual).mean().item(), rel=1e-5)
    trained, args, _ = hnn.load_run(run)       # after its one step (the loop runs total_steps + 1)
    assert args["derivative_loss"] == derivative_loss
    with torch.no_grad():
        after = torch.as_tensor(d["dxdt"], dtype=torch.float32) - trained.time_derivative(
            torch.as_tensor(d["x"], dtype=torch.float32))
    assert metrics["train_loss"] == pytest.approx(after.pow(2).mean().item(), rel=1e-5)


def test_a_derivative_loss_with_another_objective_or_an_unknown_one_is_refused(spring):
    with pytest.raises(ValueError, match="derivative_loss='l1' sets the error of a fit of dx/dt.*drop derivative_loss"):
        hnn.tasks.task_config("spring", {"objective": "trajectory", "derivative_loss": "l1"}).make_objective()
    d = spring.get_dataset(seed=0)
    with pytest.raises(ValueError, match="derivative_loss='l3': choose one of l2, l1"):
        hnn.train(hnn.build_model(2, 8), d["x"], d["dxdt"], total_steps=0, derivative_loss="l3")
