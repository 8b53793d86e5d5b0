"""A group of models that is killed resumes from its checkpoint and ends with the floats of a group that
never stopped (``hnn.trainers.group_loop.GroupCheckpoint``: ``train_closed_form``, ``train_vmap`` and ``train_group``): the
stacked weights, the Adam moments, every model's minibatch and noise samplers, the losses so far and the
members that failed before the kill."""
import json

import pytest
import torch

import hnn
import hnn.sweeps.group_runs
import hnn.trainers.closed_form
import hnn.trainers.group_loop
import hnn.trainers.vmap
from hnn.training import dxdt_loss


class _Kill(KeyboardInterrupt):
    """What a Ctrl-C or a kill mid-step does to the loop: it stops, unsaved since the last checkpoint."""


def _members(seeds=(0, 1, 2)):
    """Three HNNs of width 16 with their own inits, data and test data (the unit spring's field)."""
    models, data, tests = [], [], []
    for seed in seeds:
        torch.manual_seed(seed)
        models.append(hnn.HNN(2, hnn.MLP(2, 16, 2)))
        x = torch.randn(64, 2, generator=torch.Generator().manual_seed(10 + seed))
        dxdt = torch.stack([x[:, 1], -x[:, 0]], 1)
        data.append((x[:40 + 4 * seed], dxdt[:40 + 4 * seed]))      # rows differ: the stack pads
        tests.append((x[48:], dxdt[48:]))
    return models, data, tests


GROUP = dict(seeds=[0, 1, 2], total_steps=40, batch_size=8, input_noise=0.05, test_every=5, learn_rate=1e-2,
             names=["a", "b", "c"])


def _poison_b(kill_at=None):
    """After step 9, model b's weights turn NaN (it fails at step 10 and is dropped); after ``kill_at``, a kill."""
    def after_step(step, weights):
        if step == 9:
            with torch.no_grad():
                weights[2][1, 0, 0] = float("nan")
        if step == kill_at:
            raise _Kill
    return after_step


def _kill_at(step_to_kill):
    def after_step(step, weights):
        if step == step_to_kill:
            raise _Kill
    return after_step


def _same(models_a, stats_a, models_b, stats_b):
    for a, b in zip(models_a, models_b):
        for p, q in zip(a.state_dict().values(), b.state_dict().values()):
            assert torch.equal(p, q)
    for a, b in zip(stats_a, stats_b):
        assert (a is None) == (b is None)
        if a is not None:
            for key in ("train_loss", "test_loss", "test_steps"):
                assert a[key] == b[key], key


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=[pytest.mark.cuda, pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device here")])])
def test_a_killed_group_resumes_to_the_floats_of_an_unbroken_one(device, tmp_path, capsys):
    def members():
        models, data, tests = _members()
        return ([m.to(device) for m in models], [tuple(a.to(device) for a in d) for d in data],
                [tuple(a.to(device) for a in t) for t in tests])
    whole, data, tests = members()
    path, broken, resumed = tmp_path / "group.partial.pt", members()[0], members()[0]
    # torch's default device is meta (tests/test_devices.py): a tensor the checkpoint makes without a device fails
    torch.set_default_device("meta")
    try:
        expected, failed = hnn.trainers.closed_form.train_closed_form(whole, data, tests, **GROUP, after_step=_poison_b())
        with pytest.raises(_Kill):
            hnn.trainers.closed_form.train_closed_form(broken, data, tests, **GROUP, after_step=_poison_b(kill_at=23),
                                  checkpoint=path, checkpoint_every=0.0)
        assert path.exists()
        # a fresh process: new models, then the checkpoint's weights
        stats, failures = hnn.trainers.closed_form.train_closed_form(resumed, data, tests, **GROUP, checkpoint=path, checkpoint_every=0.0)
    finally:
        torch.set_default_device(None)
    assert list(failed) == [1]
    # b failed before the kill: the resumed group still knows it, by name and step, and never trains it again
    assert list(failures) == [1] and (failures[1].name, failures[1].step) == ("b", failed[1].step)
    _same(whole, expected, resumed, stats)
    assert len(stats[0]["train_loss"]) == GROUP["total_steps"] + 1
    assert "resuming a group of 3 at step 23 of 40" in capsys.readouterr().err


def test_a_killed_stacked_group_resumes_to_the_floats_of_an_unbroken_one(tmp_path, monkeypatch):
    # vmap over the models, AdamW with a cosine rate: a kill at the start of step 17 (the rate of each step is
    # asked for first)
    options = dict(**GROUP, optimizer="adamw", schedule="cosine", loss_of=lambda m: dxdt_loss(m, None, "l2", None))
    whole, data, tests = _members()
    expected, _ = hnn.trainers.vmap.train_vmap(whole, data, tests, **options)
    rate = hnn.trainers.group_loop.learning_rate

    def killed_at_17(learn_rate, step, total_steps, schedule):
        if step == 17:
            raise _Kill
        return rate(learn_rate, step, total_steps, schedule)
    path = tmp_path / "stacked.partial.pt"
    with monkeypatch.context() as patch, pytest.raises(_Kill):
        patch.setattr(hnn.trainers.group_loop, "learning_rate", killed_at_17)
        hnn.trainers.vmap.train_vmap(_members()[0], data, tests, **options, checkpoint=path, checkpoint_every=0.0)
    resumed = _members()[0]
    stats, _ = hnn.trainers.vmap.train_vmap(resumed, data, tests, **options, checkpoint=path, checkpoint_every=0.0)
    _same(whole, expected, resumed, stats)


def test_a_group_of_runs_resumes_and_leaves_no_checkpoint(tmp_path, monkeypatch):
    def configs(save_dir):
        return [hnn.tasks.task_config("spring", {"seed": s, "hidden_dim": 16, "total_steps": 60, "batch_size": 16,
                                                 "save_dir": str(save_dir)}) for s in (0, 1)]
    unbroken = hnn.sweeps.group_runs.train_group(configs(tmp_path / "whole"))
    fit = hnn.trainers.closed_form.train_closed_form

    def killed(*args, **kwargs):
        return fit(*args, **kwargs, checkpoint_every=0.0, after_step=_kill_at(30))
    with monkeypatch.context() as patch, pytest.raises(_Kill):
        patch.setattr(hnn.trainers.closed_form, "train_closed_form", killed)
        hnn.sweeps.group_runs.train_group(configs(tmp_path / "broken"))
    partial = hnn.sweeps.group_runs.group_checkpoint(configs(tmp_path / "broken"))
    assert partial.exists() and partial.parent == tmp_path / "broken" and partial.name.startswith(".group-")
    # another group (other seeds) does not take this group's checkpoint
    assert hnn.sweeps.group_runs.group_checkpoint(configs(tmp_path / "broken")[:1]) != partial
    resumed = hnn.sweeps.group_runs.train_group(configs(tmp_path / "broken"))
    assert not partial.exists()
    for a, b in zip(unbroken, resumed):
        history = [json.loads((folder / "metrics.json").read_text())["history"] for folder in (a, b)]
        assert history[0]["train_loss"] == history[1]["train_loss"]
        for p, q in zip(hnn.load_run(a)[0].state_dict().values(), hnn.load_run(b)[0].state_dict().values()):
            assert torch.equal(p, q)


def test_a_killed_groups_checkpoint_is_dropped_once_its_runs_are_saved_by_other_groups(tmp_path, monkeypatch):
    configs = [hnn.tasks.task_config("spring", {"seed": s, "hidden_dim": 16, "total_steps": 40, "batch_size": 16,
                                                "save_dir": str(tmp_path)}) for s in (0, 1)]
    fit = hnn.trainers.closed_form.train_closed_form

    def killed(*args, **kwargs):
        return fit(*args, **kwargs, checkpoint_every=0.0, after_step=_kill_at(20))
    with monkeypatch.context() as patch, pytest.raises(_Kill):
        patch.setattr(hnn.trainers.closed_form, "train_closed_form", killed)
        hnn.sweeps.group_runs.train_group(configs)
    spent = hnn.sweeps.group_runs.group_checkpoint(configs)
    unreadable = tmp_path / ".group-000000000000.partial.pt"
    unreadable.write_bytes(b"half a file")
    # a rerun that no longer forms that group (each run alone, as if the other had been saved meanwhile) leaves
    # the checkpoint while one of its runs is still missing, and drops it once both are saved
    hnn.sweeps.group_runs.train_group(configs[:1])
    assert spent.exists()
    hnn.sweeps.group_runs.train_group(configs[1:])
    assert not spent.exists() and unreadable.exists()
    assert hnn.sweeps.group_runs.drop_spent_checkpoints(tmp_path) == []


def test_a_checkpoint_of_another_group_is_refused_with_its_fix(tmp_path):
    models, data, tests = _members()
    path = tmp_path / "group.partial.pt"
    with pytest.raises(_Kill):
        hnn.trainers.closed_form.train_closed_form(models, data, tests, **GROUP, after_step=_kill_at(5), checkpoint=path,
                              checkpoint_every=0.0)
    two, data2, tests2 = _members((0, 1))
    with pytest.raises(ValueError, match=r"is of another model \(its stacked weights are of shapes .*delete .* to "
                                         r"train from the start"):
        hnn.trainers.closed_form.train_closed_form(two, data2, tests2, **{**GROUP, "seeds": [0, 1], "names": ["a", "b"]}, checkpoint=path)
