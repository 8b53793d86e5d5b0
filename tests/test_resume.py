"""A training run that is killed resumes from its checkpoint and ends with the floats of a run that never
stopped: the weights, the Adam moments, the minibatch and noise samplers and the loss history all
carry over (``hnn.train(checkpoint=...)``, ``hnn.run_experiment``)."""
import json

import pytest
import torch

import hnn
import hnn.runs
import hnn.sweeps.sweep
import hnn.training


def _data(seed=0):
    gen = torch.Generator().manual_seed(seed)
    x = torch.randn(64, 2, generator=gen)
    dxdt = torch.stack([x[:, 1], -x[:, 0]], 1)        # the unit spring's field: dq/dt = p, dp/dt = -q
    return x[:48], dxdt[:48], x[48:], dxdt[48:]


def _model():
    torch.manual_seed(0)
    return hnn.HNN(2, hnn.MLP(2, 16, 2))


# minibatches, input noise and a cosine rate: every sampler and schedule the loop keeps state for
OPTIONS = dict(total_steps=40, batch_size=8, input_noise=0.05, optimizer="adamw", schedule="cosine",
               learn_rate=1e-2, test_every=5)


class _Kill(KeyboardInterrupt):
    """What a Ctrl-C or a kill between two steps does to the loop: it stops, unsaved."""


def _stop_at(step: int):
    def callback(done, total):
        if done == step + 1:
            raise _Kill
    return callback


def test_a_killed_run_resumes_to_the_floats_of_an_unbroken_one(tmp_path):
    whole = _model()
    expected = hnn.train(whole, *_data(), **OPTIONS)

    path = tmp_path / "run.partial.pt"
    broken = _model()
    with pytest.raises(_Kill):
        hnn.train(broken, *_data(), **OPTIONS, checkpoint=path, checkpoint_every=0.0, on_step=_stop_at(23))
    assert path.exists()
    resumed = _model()              # a fresh process: the weights of a new model, then the checkpoint's
    stats = hnn.train(resumed, *_data(), **OPTIONS, checkpoint=path, checkpoint_every=0.0)

    for a, b in zip(whole.state_dict().values(), resumed.state_dict().values()):
        assert torch.equal(a, b)
    for key in ("train_loss", "test_loss", "test_steps"):
        assert stats[key] == expected[key]
    assert len(stats["train_loss"]) == OPTIONS["total_steps"] + 1


def test_the_generators_of_a_custom_loss_resume_where_they_stopped(tmp_path):
    # a loss with noise of its own (the pixel objective's latent noise): its generator is checkpointed too
    def run(model, path=None, stop=None):
        noise = torch.Generator().manual_seed(7)

        def loss(x, y):
            return ((model.time_derivative(x + 0.1 * torch.randn(x.shape, generator=noise)) - y) ** 2).mean(1)
        return hnn.train(model, *_data(), total_steps=30, loss=loss, checkpoint=path, checkpoint_every=0.0,
                         generators=(noise,), on_step=_stop_at(stop) if stop else None)
    expected = run(_model())
    path = tmp_path / "run.partial.pt"
    with pytest.raises(_Kill):
        run(_model(), path, stop=13)
    assert run(_model(), path)["train_loss"] == expected["train_loss"]


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=[pytest.mark.cuda, pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device here")])])
def test_a_run_resumes_on_the_model_device_making_nothing_on_the_default_one(device, tmp_path):
    # torch's default device is meta (tests/test_devices.py): a tensor the resume makes without a device fails
    path, models = tmp_path / "run.partial.pt", [_model().to(device) for _ in range(3)]
    data = [a.to(device) for a in _data()]
    torch.set_default_device("meta")
    try:
        expected = hnn.train(models[0], *data, **OPTIONS)
        with pytest.raises(_Kill):
            hnn.train(models[1], *data, **OPTIONS, checkpoint=path, checkpoint_every=0.0, on_step=_stop_at(11))
        stats = hnn.train(models[2], *data, **OPTIONS, checkpoint=path, checkpoint_every=0.0)
    finally:
        torch.set_default_device(None)
    assert stats["train_loss"] == expected["train_loss"]
    assert all(p.device.type == device for p in models[2].parameters())


def test_a_checkpoint_of_another_run_is_refused_with_the_fix(tmp_path):
    path = tmp_path / "run.partial.pt"
    with pytest.raises(_Kill):
        hnn.train(_model(), *_data(), **OPTIONS, checkpoint=path, checkpoint_every=0.0, on_step=_stop_at(5))
    with pytest.raises(ValueError, match="run of 40 steps, not 60; delete .* to train from the start"):
        hnn.train(_model(), *_data(), **{**OPTIONS, "total_steps": 60}, checkpoint=path)
    torch.manual_seed(0)
    wider = hnn.HNN(2, hnn.MLP(2, 32, 2))
    with pytest.raises(ValueError, match="is of another model"):
        hnn.train(wider, *_data(), **OPTIONS, checkpoint=path)
    path.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="cannot be read.*delete"):
        hnn.train(_model(), *_data(), **OPTIONS, checkpoint=path)


def _config(save_dir, **fields):
    return hnn.load_task("spring", "train").Config(save_dir=str(save_dir), total_steps=30, hidden_dim=8, **fields)


def test_a_run_interrupted_mid_training_resumes_and_leaves_no_checkpoint(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(hnn.trainers.checkpoint, "CHECKPOINT_EVERY", 0.0)
    unbroken = hnn.run_experiment(_config(tmp_path / "a"))

    config = _config(tmp_path / "b")
    partial = hnn.runs.partial_checkpoint(config)
    with pytest.raises(_Kill):
        hnn.run_experiment(config, on_step=_stop_at(17))
    assert partial.exists() and hnn.runs.find_run(config) is None
    _, todo = hnn.sweeps.sweep.reuse([hnn.sweeps.sweep.Job("b", "spring", config)])
    assert [job.key for job in todo] == ["b"] and "b has a training checkpoint" in capsys.readouterr().out
    resumed = hnn.run_experiment(config)
    assert not partial.exists()
    metrics = [json.loads((run / "metrics.json").read_text()) for run in (unbroken, resumed)]
    for key in ("train_loss", "test_loss"):
        assert metrics[0][key] == metrics[1][key]
    # --force trains from the start: the checkpoint of an interrupted attempt is dropped
    with pytest.raises(_Kill):
        hnn.run_experiment(_config(tmp_path / "c"), on_step=_stop_at(9))
    forced = _config(tmp_path / "c", force=True)
    calls = []
    hnn.run_experiment(forced, on_step=lambda done, total: calls.append(done))
    assert calls[0] == 1 and not hnn.runs.partial_checkpoint(forced).exists()


def test_a_run_that_fails_in_training_leaves_no_checkpoint(tmp_path, monkeypatch):
    monkeypatch.setattr(hnn.trainers.checkpoint, "CHECKPOINT_EVERY", 0.0)

    def fail(done, total):
        if done == 12:
            raise hnn.DivergenceError("a singular field, say")
    config = _config(tmp_path)
    with pytest.raises(hnn.DivergenceError):
        hnn.run_experiment(config, on_step=fail)
    assert not hnn.runs.partial_checkpoint(config).exists()
