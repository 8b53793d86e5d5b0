"""Run folders are written as a whole: an interrupted save never mixes two runs."""
import dataclasses
import json
import re
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import torch

import hnn
import hnn.runs

REPO = Path(__file__).resolve().parent.parent
_UMASK = hnn.io.UMASK


def _args(save_dir, steps: int):
    """The spring task's config of a run with ``total_steps=steps`` (other steps, another folder)."""
    return hnn.load_task("spring", "train").Config(save_dir=str(save_dir), total_steps=steps, hidden_dim=8)


def _saved(config) -> dict:
    return {**config.to_dict(), "kind": config.kind}


def _save(args, fill: float, directory=None):
    """A small model with every parameter ``fill``, saved as the run of ``args`` (or in
    ``directory``); returns its folder."""
    model = hnn.runs.model_from_args(_saved(args))
    with torch.no_grad():
        for p in model.parameters():
            p.fill_(fill)
    return hnn.runs.save_run(directory or hnn.runs.run_dir(args), model, _saved(args), {"train_loss": fill})


def _snapshot(directory: Path) -> dict:
    """``{file name: bytes}`` of a folder."""
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def _hidden(save_dir: Path) -> list[str]:
    return sorted(p.name for p in save_dir.iterdir() if p.name.startswith("."))


def _assert_old_run_intact(old, new, before: dict) -> None:
    run = hnn.runs.run_dir(old)
    assert _snapshot(run) == before
    assert hnn.runs.find_run(old) == run and hnn.runs.find_run(new) is None
    model, args, metrics = hnn.load_run(run)
    assert args["total_steps"] == old.total_steps and metrics["train_loss"] == 0.25
    assert all((p == 0.25).all() for p in model.parameters())


@pytest.mark.parametrize("failing", ["args.json", "metrics.json", hnn.runs.COMPLETE])
def test_a_save_failing_between_files_leaves_the_old_run(failing, tmp_path, monkeypatch):
    old, new = _args(tmp_path, 2), _args(tmp_path, 3)
    before = _snapshot(_save(old, 0.25))
    real = hnn.runs.write_json

    def write_json(path, obj):
        if Path(path).name == failing:
            raise OSError("disk full")
        real(path, obj)

    monkeypatch.setattr(hnn.runs, "write_json", write_json)
    with pytest.raises(OSError, match="disk full"):
        _save(new, 0.5, hnn.runs.run_dir(old))
    _assert_old_run_intact(old, new, before)
    assert _hidden(tmp_path) == []                     # the half-filled folder is removed


def test_a_failed_move_puts_the_old_run_back(tmp_path, monkeypatch):
    old, new = _args(tmp_path, 2), _args(tmp_path, 3)
    before = _snapshot(_save(old, 0.25))
    real = os.rename

    def rename(src, dst):
        if ".tmp-" in Path(src).name:
            raise OSError("rename refused")
        real(src, dst)

    monkeypatch.setattr(hnn.io.os, "rename", rename)
    with pytest.raises(OSError, match="rename refused"):
        _save(new, 0.5, hnn.runs.run_dir(old))
    monkeypatch.undo()
    _assert_old_run_intact(old, new, before)
    assert _hidden(tmp_path) == []


# a child process that saves a run of total_steps 3 into the folder of the one of 2, and is SIGKILLed when
# `kill_at` happens: before the last file is written, or between moving the old folder aside and
# moving the new one in
_KILLED_SAVE = """
import os, signal, sys
from pathlib import Path
import hnn, hnn.runs, torch
save_dir, kill_at = sys.argv[1], sys.argv[2]
real_write, real_rename = hnn.runs.write_json, os.rename

def write_json(path, obj):
    if Path(path).name == kill_at:
        os.kill(os.getpid(), signal.SIGKILL)
    real_write(path, obj)

def rename(src, dst):
    real_rename(src, dst)
    if kill_at == "aside" and ".old-" in Path(dst).name:
        os.kill(os.getpid(), signal.SIGKILL)

hnn.runs.write_json, os.rename = write_json, rename
Config = hnn.load_task("spring", "train").Config
old, new = Config(save_dir=save_dir, total_steps=2, hidden_dim=8), Config(save_dir=save_dir, total_steps=3, hidden_dim=8)
hnn.runs.save_run(hnn.runs.run_dir(old), hnn.build_model(2, 8), {**new.to_dict(), "kind": "hnn"}, {"train_loss": 0.5})
"""


def _killed_save(save_dir: Path, kill_at: str) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", _KILLED_SAVE, str(save_dir), kill_at], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == -9, proc.stderr          # killed, not finished nor failed


@pytest.mark.skipif(sys.platform == "win32", reason="needs SIGKILL")
@pytest.mark.parametrize("kill_at", ["metrics.json", hnn.runs.COMPLETE])
def test_a_save_killed_between_files_leaves_the_old_run(kill_at, tmp_path):
    old, new = _args(tmp_path, 2), _args(tmp_path, 3)
    before = _snapshot(_save(old, 0.25))
    _killed_save(tmp_path, kill_at)
    _assert_old_run_intact(old, new, before)
    leftover = _hidden(tmp_path)
    assert len(leftover) == 1 and leftover[0].startswith(".spring-hnn-seed0-")   # never looked at
    assert ".tmp-" in leftover[0]
    # a later save into that folder replaces the old run, whatever was left over
    run = _save(new, 0.5, hnn.runs.run_dir(old))
    assert hnn.load_run(run)[1]["total_steps"] == 3 and _hidden(tmp_path) == leftover


@pytest.mark.skipif(sys.platform == "win32", reason="needs SIGKILL")
def test_a_save_killed_between_the_renames_leaves_no_run(tmp_path):
    old = _args(tmp_path, 2)
    before = _snapshot(_save(old, 0.25))
    _killed_save(tmp_path, "aside")
    # nothing at the run's path: it trains anew; the old run waits whole in .old-*
    assert not hnn.runs.run_dir(old).exists()
    assert hnn.runs.find_run(old) is None
    [aside] = [p for p in tmp_path.iterdir() if ".old-" in p.name]
    assert _snapshot(aside) == before
    run = _save(old, 0.5)
    assert hnn.runs.find_run(old) == run


def test_a_save_replaces_the_old_run_whole_with_ordinary_permissions(tmp_path):
    old, new = _args(tmp_path, 2), _args(tmp_path, 3)
    run = _save(old, 0.25)
    (run / "rollout.npz").write_bytes(b"of the old model")     # written after a save, as pixel runs do
    assert hnn.runs.find_run(old) == run
    assert _save(new, 0.5, run) == run
    assert sorted(p.name for p in run.iterdir()) == ["args.json", hnn.runs.COMPLETE, "metrics.json", "model.tar"]
    assert _hidden(tmp_path) == []
    model, args, metrics = hnn.load_run(run)
    assert args == json.loads(json.dumps(_saved(new))) and metrics["train_loss"] == 0.5
    assert all((p == 0.5).all() for p in model.parameters())
    assert run.stat().st_mode & 0o777 == 0o777 & ~_UMASK
    assert all(p.stat().st_mode & 0o777 == 0o666 & ~_UMASK for p in run.iterdir())
    # files added after the save keep the run complete
    hnn.runs.write_json(run / "metrics.json", {**metrics, "energy_mse": 1.0})
    assert hnn.runs.find_run(old) == run


@pytest.mark.parametrize("damage", ["no mark", "file missing"])
def test_an_incomplete_folder_is_neither_reused_nor_loaded(damage, tmp_path):
    args = _args(tmp_path, 2)
    run = _save(args, 0.25)
    (run / (hnn.runs.COMPLETE if damage == "no mark" else "metrics.json")).unlink()
    assert hnn.runs.find_run(args) is None
    with pytest.raises(RuntimeError, match="interrupted.*delete the folder and retrain"):
        hnn.load_run(run)


# ----------------------------------------------------------------------------------------------
# one runner for every model kind: args.json says which kind and which cached dataset


@pytest.mark.parametrize("task, extra, kind, cached", [
    ("spring", [], "hnn", False), ("spring", ["--baseline"], "baseline", False), ("2body", [], "hnn", True)])
def test_args_json_records_the_model_kind_and_the_dataset_cache(task, extra, kind, cached, tmp_path):
    run = hnn.load_task(task, "train").main(["--total_steps", "1", "--save_dir", str(tmp_path)] + extra)
    saved = json.loads((run / "args.json").read_text())
    assert saved["model"] == kind
    if cached:       # the .npz the run trained on, beside the run, is what evaluation rebuilds from its args
        assert saved["dataset_cache_key"].startswith(f"{task}-") and (tmp_path / saved["dataset_cache_key"]).is_file()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert hnn.tasks.run_dataset(task, saved)["cache_key"] == saved["dataset_cache_key"]
        with pytest.warns(UserWarning, match="trained on the cached dataset 2body-old.npz"):
            hnn.tasks.run_dataset(task, {**saved, "dataset_cache_key": "2body-old.npz"})
    else:
        assert saved["dataset_cache_key"] is None
    assert hnn.load_run(run)[1] == saved and saved["kind"] == kind


def test_a_saved_kind_decides_the_model_and_an_unknown_one_is_named():
    saved = _saved(_args(".", 2))
    assert isinstance(hnn.runs.model_from_args(saved), hnn.HNN)
    pixel = {**saved, "input_dim": 8, "latent_dim": 2, "hidden_dim": 4, "kind": "pixel-hnn"}
    assert isinstance(hnn.runs.model_from_args(pixel), hnn.PixelHNN)
    with pytest.raises(ValueError, match="unknown model kind 'sideways'.*pixel-hnn"):
        hnn.runs.model_from_args({**saved, "kind": "sideways"})


def test_a_custom_objective_trains_through_the_one_runner(tmp_path):
    class Halved(hnn.DerivativeObjective):
        """Fits half of dx/dt, from arrays of other names (a toy, to show the runner asks the objective)."""
        arrays = ("a", "b", "test_a", "test_b")

    data = hnn.load_task("spring").get_dataset()
    renamed = {"a": data["x"], "b": data["dxdt"] / 2, "test_a": data["test_x"], "test_b": data["test_dxdt"] / 2}
    run = hnn.run_experiment(_args(tmp_path, 3), renamed, Halved())
    assert json.loads((run / "args.json").read_text())["kind"] == "hnn"
    with pytest.raises(KeyError, match=r"lacks \['a', 'b', 'test_a', 'test_b'\]"):
        hnn.run_experiment(_args(tmp_path, 3), data, Halved())


def test_display_only_fields_and_save_dir_are_not_the_identity(tmp_path):
    Pixels = hnn.load_task("pixels", "train").Config
    assert set(Pixels.display_only()) == {"verbose", "print_every", "debug", "force", "render_workers", "no_eval",
                                          "threads"}
    base = Pixels(save_dir=str(tmp_path))
    for same in (dict(verbose=True), dict(render_workers=3, no_eval=True), dict(save_dir=str(tmp_path / "b")),
                 dict(threads=2)):
        assert dataclasses.replace(base, **same).key() == base.key(), same
    for other in (dict(trials=50), dict(model="baseline"), dict(learn_rate=2e-3), dict(seed=1)):
        assert dataclasses.replace(base, **other).key() != base.key(), other


def test_train_fraction_draws_a_seeded_ordered_subset_of_the_training_rows():
    x = torch.arange(40.0).reshape(20, 2)
    y = -x
    sub_x, sub_y = hnn.policy.training_subset(x, y, 0.25, seed=3)
    assert len(sub_x) == 5 and torch.equal(sub_y, -sub_x)
    rows = (sub_x[:, 0] / 2).long()
    assert torch.all(rows[1:] > rows[:-1])                        # the rows keep their order
    assert torch.equal(hnn.policy.training_subset(x, y, 0.25, seed=3)[0], sub_x)
    assert not torch.equal(hnn.policy.training_subset(x, y, 0.25, seed=4)[0], sub_x)
    assert hnn.policy.training_subset(x, y, 1.0, seed=3)[0] is x
    assert len(hnn.policy.training_subset(x, y, 0.01, seed=0)[0]) == 1   # never empty
    with pytest.raises(ValueError, match="train_fraction"):
        hnn.policy.training_subset(x, y, 0.0, seed=0)


def test_a_run_trains_on_its_fraction(tmp_path, monkeypatch):
    seen = []
    real_loop = hnn.trainers.lone.run_loop          # the lone loop a prepared run trains through
    monkeypatch.setattr(hnn.trainers.lone, "run_loop",
                        lambda model, loss, x, *a, **k: seen.append(len(x)) or real_loop(model, loss, x, *a, **k))
    trainer = hnn.load_task("spring", "train")
    argv = ["--save_dir", str(tmp_path), "--total_steps", "2", "--hidden_dim", "8"]
    folder = trainer.main(argv + ["--train_fraction", "0.1", "--name", "small"])
    assert seen == [75]                                            # 10% of spring's 750 training rows
    assert json.loads((folder / "args.json").read_text())["train_fraction"] == 0.1
    full = trainer.main(argv)
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv)) == full
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv + ["--train_fraction", "0.5"])) is None


def test_a_full_disk_is_one_error_line_naming_the_folder_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    """A write that fails while a run saves (the disk full: every write raises ENOSPC) ends a train.py with one
    ``error:`` line naming the folder and the cause, not torch's traceback; the folder holds no run, no
    temporary folder and no checkpoint. torch's own writer reports a full disk as a RuntimeError, which is
    why the run's files are serialized in memory and written as plain bytes: here both writes fail alike."""
    import errno
    import pathlib

    def full(self, data, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(self))
    monkeypatch.setattr(pathlib.Path, "write_bytes", full)
    monkeypatch.setattr(pathlib.Path, "write_text", full)
    train = hnn.load_task("spring", "train")
    with pytest.raises(SystemExit) as info:
        hnn.command.run_main(train.main, ["--total_steps", "2", "--hidden_dim", "8", "--save_dir", str(tmp_path)])
    assert info.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len([line for line in lines if line.startswith("error:")]) == 1 and lines[-1].startswith("error:")
    assert re.search(rf"error: \[Errno {errno.ENOSPC}\] cannot write in {re.escape(str(tmp_path))}: No space left on "
                     r"device; nothing half-written was left there\. Free space", lines[-1])
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(".npz")) == []


def test_prepare_is_what_a_run_trains_and_what_its_training_cost_times(tmp_path, monkeypatch):
    """A run trains ``prepare``'s model on its rows with its options: the same steps from it give the saved
    weights bit for bit; the training-cost measurement times the run's own loop (its optimizer, schedule and
    clipping, which it once dropped, timing plain Adam)."""
    from hnn_analysis.training_cost import training_cost
    config = hnn.tasks.task_config("spring", {"optimizer": "adamw", "schedule": "cosine", "clip_grad": 1.0,
                                             "total_steps": 30, "hidden_dim": 16, "save_dir": str(tmp_path)})
    prep = hnn.prepare(config)
    kwargs = prep.train_kwargs()
    assert (kwargs["optimizer"], kwargs["schedule"], kwargs["clip_grad"], kwargs["total_steps"]) == ("adamw", "cosine", 1.0, 30)
    hnn.train(prep.canonical_model, prep.x, prep.y, prep.test_x, prep.test_y, **kwargs)
    saved = hnn.load_run(hnn.run_experiment(config))[0]
    for key, value in prep.model.state_dict().items():
        assert torch.equal(value, saved.state_dict()[key]), key
    seen = []
    real_train = hnn.train
    monkeypatch.setattr(hnn, "train", lambda *a, **kw: seen.append(kw) or real_train(*a, **kw))
    training_cost("spring", hnn.load_run(hnn.runs.find_run(config))[1], bursts=1, burst_seconds=0.01)
    assert seen and all((kw["optimizer"], kw["schedule"], kw["clip_grad"]) == ("adamw", "cosine", 1.0) for kw in seen)
