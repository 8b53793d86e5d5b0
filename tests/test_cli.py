"""The command line of every train.py: a bad flag or value is one ``error:`` line and exit code 2,
never a traceback; ``--debug`` shows it; a good run prints where it was saved.

Most parse errors are checked in-process (argparse raises SystemExit); a handful run the
script as a subprocess, the way a user does.
"""
import dataclasses
import functools
import shutil
from pathlib import Path
import os
import subprocess
import sys

import pytest

import hnn
from hnn.runs import find_run

REPO = hnn.tasks.repo_root()


def _error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("error:")]


def _assert_one_error(err: str, *names: str) -> str:
    """The single ``error:`` line of stderr ``err``, checked to name each of ``names``."""
    lines = _error_lines(err)
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for name in names:
        assert name in lines[0], lines[0]
    return lines[0]


# ----------------------------------------------------------------------------------------------
# parse errors, in-process

BAD_FLAGS = [
    ("spring", ["--nonlinearity", "foo"], ["'foo'", "tanh", "swish"]),
    ("spring", ["--input_dim", "3"], ["--input_dim: 3 does not match", "spring task", "width 2", "pass --input_dim 2"]),
    ("pend", ["--input_dim", "4"], ["4", "pend task", "width 2"]),
    ("real", ["--input_dim", "1"], ["1", "real task", "width 2"]),
    ("2body", ["--input_dim", "2"], ["2", "2body task", "width 8", "pass --input_dim 8"]),
    ("3body", ["--input_dim", "8"], ["8", "3body task", "width 12"]),
    ("pixels", ["--input_dim", "2"], ["2", "pixels task", "width 1568"]),
    ("spring", ["--input_dim", "two"], ["'two'", "pass --input_dim 2"]),
    ("spring", ["--total_steps", "-5"], ["--total_steps", "'-5'", ">= 0"]),
    ("spring", ["--hidden_dim", "0"], ["--hidden_dim", "'0'", ">= 1"]),
    ("spring", ["--learn_rate", "0"], ["--learn_rate", "'0'", "> 0"]),
    ("pend", ["--learn_rate", "-1e-3"], ["--learn_rate", "'-1e-3'"]),
    ("pend", ["--learn_rate", "nan"], ["--learn_rate", "'nan'"]),
    ("spring", ["--train_fraction", "1.5"], ["--train_fraction", "'1.5'", "in (0, 1]"]),
    ("real", ["--split", "theirs"], ["--split", "theirs", "dhnn"]),
    ("spring", ["--print_every", "0"], ["--print_every", "'0'", ">= 1"]),
    ("spring", ["--weight_decay", "-1e-4"], ["--weight_decay", "'-1e-4'", ">= 0"]),
    ("2body", ["--batch_size", "-3"], ["--batch_size", "'-3'", "none/0/full"]),
    ("spring", ["--field_type", "sideways"], ["'sideways'", "solenoidal", "conservative", "both"]),
    ("spring", ["--seed", "-1"], ["--seed", "'-1'"]),
    ("spring", ["--device", "gpu0"], ["'gpu0'", "cpu"]),
    ("spring", ["--dtype", "float16"], ["'float16'", "float64"]),
    ("spring", ["--no_such_flag"], ["--no_such_flag"]),
    ("2body", ["--input_noise", "-0.1"], ["--input_noise", "'-0.1'"]),
    ("pixels", ["--latent_dim", "3"], ["--latent_dim", "'3'", "even"]),
    ("pixels", ["--latent_dim", "0"], ["--latent_dim", "'0'"]),
    ("pixels", ["--trials", "4"], ["--trials", "'4'", ">= 5"]),
    ("pixels", ["--timesteps", "3"], ["--timesteps", "'3'", ">= 4"]),
    ("pixels", ["--render_size", "0"], ["--render_size", "'0'", ">= 1"]),
    ("pixels", ["--render_workers", "0"], ["--render_workers", "'0'"]),
    ("pixels", ["--ae_nonlinearity", "foo"], ["--ae_nonlinearity", "'foo'", "relu"]),
]


@pytest.mark.parametrize("task, argv, names", BAD_FLAGS, ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_bad_flag_is_one_error_line(task, argv, names, capsys):
    with pytest.raises(SystemExit) as info:
        hnn.cli.parse(hnn.load_task(task, "train").Config, argv)
    assert info.value.code == 2
    _assert_one_error(capsys.readouterr().err, *names)


@pytest.mark.parametrize("task, width", [("spring", 2), ("pend", 2), ("real", 2), ("2body", 8), ("3body", 12),
                                         ("pixels", 1568)])
def test_defaults_and_the_task_width_parse(task, width):
    parse = functools.partial(hnn.cli.parse, hnn.load_task(task, "train").Config)
    assert parse([]).input_dim == width
    assert parse(["--input_dim", str(width)]).input_dim == width
    assert parse([]).debug is False


def test_good_values_keep_their_meaning():
    parse = functools.partial(hnn.cli.parse, hnn.load_task("spring", "train").Config)
    for text in ("none", "0", "full", "FULL"):
        assert parse(["--batch_size", text]).batch_size is None
    assert parse(["--batch_size", "32"]).batch_size == 32
    for name in hnn.models.NONLINEARITIES:
        assert parse(["--nonlinearity", name]).nonlinearity == name
    args = parse(["--total_steps", "0", "--weight_decay", "0", "--learn_rate", "1e-2", "--field_type", "both",
                  "--device", "cpu"])
    assert (args.total_steps, args.weight_decay, args.learn_rate, args.field_type) == (0, 0.0, 1e-2, "both")
    assert hnn.cli.parse(hnn.load_task("pixels", "train").Config, ["--latent_dim", "4", "--trials", "5"]).latent_dim == 4


# ----------------------------------------------------------------------------------------------
# the run_main handler, in-process


def _raises(err):
    def main(argv):
        raise err
    return main


def test_run_main_turns_an_input_error_into_one_line(capsys):
    with pytest.raises(SystemExit) as info:
        hnn.command.run_main(_raises(ValueError("bad value 7\n  for --thing; pass 8")), [])
    assert info.value.code == 2
    assert capsys.readouterr().err == "error: bad value 7 for --thing; pass 8\n"


def test_run_main_debug_reraises():
    with pytest.raises(FileNotFoundError, match="nowhere"):
        hnn.command.run_main(_raises(FileNotFoundError("nowhere")), ["--seed", "1", "--debug"])


def test_no_flag_is_an_abbreviation_and_a_misspelling_gets_the_nearest_flag(capsys):
    Config = hnn.load_task("spring", "train").Config
    for argv, hint in ((["--total_step", "30"], "did you mean --total_steps?"),
                       (["--deb"], "did you mean --debug?"),
                       (["--hiden_dim=8"], "--hiden_dim: did you mean --hidden_dim?")):
        with pytest.raises(SystemExit) as info:
            hnn.cli.parse(Config, argv)
        assert info.value.code == 2
        assert hint in _assert_one_error(capsys.readouterr().err, argv[0].split("=")[0])
    with pytest.raises(SystemExit):
        hnn.cli.parse(Config, ["--zzzz"])
    assert "did you mean" not in capsys.readouterr().err      # nothing near: no guess


def test_a_flags_words_decide_before_its_letters():
    known = ["--fit", "--field_type", "--total_steps", "--learn_rate", "--hidden_dim", "--seed", "--save_dir"]
    for typed, meant in (("--fit-type", "--fit"),          # its first word is a flag: not the letters' --field_type
                         ("--total-steps", "--total_steps"),    # '-' for '_'
                         ("--total", "--total_steps"),          # starts one flag only
                         ("--learn_rates", "--learn_rate"),     # no word matches: the nearest spelling
                         ("--zzzz", None)):
        assert hnn.cli.nearest_flag(typed, known) == meant, typed


def test_ctrl_c_is_one_line_and_exit_130(capsys):
    with pytest.raises(SystemExit) as info:
        hnn.command.run_main(_raises(KeyboardInterrupt()), [])
    assert info.value.code == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("interrupted:") and "discarded" in err and "stays" in err
    with pytest.raises(KeyboardInterrupt):
        hnn.command.run_main(_raises(KeyboardInterrupt()), ["--debug"])


def test_a_misspelled_choice_gets_the_nearest_one(capsys):
    Config = hnn.load_task("spring", "train").Config
    for argv, hint in ((["--model", "seperable"], "did you mean 'separable'?"),
                       (["--nonlinearity", "tahn"], "did you mean 'tanh'?")):
        with pytest.raises(SystemExit):
            hnn.cli.parse(Config, argv)
        assert _assert_one_error(capsys.readouterr().err, argv[0], repr(argv[1])).endswith(hint)
    with pytest.raises(SystemExit):
        hnn.cli.parse(Config, ["--model", "zzzz"])
    assert "did you mean" not in capsys.readouterr().err
    with pytest.raises(ValueError, match="did you mean 'separable'"):
        hnn.cli.check(Config(model="seperable"))


@pytest.mark.parametrize("stop", [KeyboardInterrupt(), ValueError("a bad input found while running")])
def test_a_run_stopped_before_saving_leaves_no_save_dir_it_created(tmp_path, monkeypatch, stop):
    Config = hnn.load_task("spring", "train").Config
    monkeypatch.setattr(hnn.runs, "run_experiment", _raises(stop))
    (tmp_path / "kept").mkdir()
    for save_dir in (tmp_path / "new" / "deeper", tmp_path / "kept" / "new", tmp_path / "kept"):
        with pytest.raises(type(stop)):
            hnn.command.train(Config, ["--total_steps", "2", "--save_dir", str(save_dir)])
        # the folders it created are removed again; the one that was there stays
        assert [p.name for p in tmp_path.iterdir()] == ["kept"] and not any((tmp_path / "kept").iterdir())


def test_run_main_leaves_bugs_alone():
    with pytest.raises(ZeroDivisionError):
        hnn.command.run_main(_raises(ZeroDivisionError("a bug, not bad input")), [])


def test_a_rerun_reuses_the_complete_run_and_force_replaces_it(tmp_path, capsys):
    Config = hnn.load_task("spring", "train").Config
    save_dir = tmp_path / "new" / "deeper"
    argv = ["--total_steps", "2", "--hidden_dim", "8", "--save_dir", str(save_dir)]
    run = hnn.command.train(Config, argv)
    assert capsys.readouterr().out.splitlines()[-1] == f"saved the run to {run} (created {save_dir}, which did not exist)"
    stamp = (run / "model.tar").stat().st_mtime_ns
    # display-only flags (print_every, verbose) are not a new run: the same folder, reused, nothing trained
    assert hnn.command.train(Config, argv + ["--print_every", "7"]) == run
    assert capsys.readouterr().out.splitlines()[-1].startswith(f"reused the complete run at {run}: ")
    assert (run / "model.tar").stat().st_mtime_ns == stamp
    assert hnn.command.train(Config, argv + ["--force"]) == run
    line = capsys.readouterr().out.splitlines()[-1]
    assert line == f"saved the run to {run} (replaced the complete run of the same settings that was there (--force))"
    assert hnn.load_run(run)[1]["total_steps"] == 2


def test_the_thread_count_is_the_runs_own_recorded_and_outside_its_identity(tmp_path, capsys):
    import torch
    Config = hnn.load_task("spring", "train").Config
    assert Config().threads == 1 and "threads" in Config.display_only()
    assert Config(threads=2).key() == Config().key()
    caller = torch.get_num_threads()
    argv = ["--total_steps", "2", "--hidden_dim", "8", "--save_dir", str(tmp_path)]
    run = hnn.command.train(Config, argv + ["--threads", "2"])
    assert torch.get_num_threads() == caller                  # the caller's count is back
    args, metrics = hnn.load_run(run)[1:3]
    assert args["threads"] == 2 and metrics["torch_threads"] == 2
    assert hnn.command.train(Config, argv) == run                 # another count: the same run, reused
    assert capsys.readouterr().out.splitlines()[-1].startswith("reused")
    hnn.command.train(Config, argv + ["--force"])                 # the default: one thread, recorded
    assert hnn.load_run(run)[1]["threads"] == 1 == hnn.load_run(run)[2]["torch_threads"]
    # from Python a run keeps the caller's count, and records it
    torch.set_num_threads(2)
    try:
        folder = hnn.run_experiment(Config(total_steps=2, hidden_dim=8, seed=1, save_dir=str(tmp_path)))
    finally:
        torch.set_num_threads(caller)
    assert hnn.load_run(folder)[1]["threads"] == 2


def test_display_only_flags_stay_out_of_the_identity():
    Config = hnn.load_task("spring", "train").Config
    base = Config()
    for field in ("print_every", "verbose", "debug", "force"):
        assert field in Config.display_only()
    other = Config(print_every=7, verbose=True, debug=True, force=True, save_dir="elsewhere")
    assert other.key() == base.key() and hnn.runs.run_dir(other).name == hnn.runs.run_dir(base).name
    assert Config(total_steps=7).key() != base.key()       # a field that changes what is trained does


def test_a_field_added_later_enters_the_identity_only_away_from_its_default():
    """--init and --derivative_loss came after runs were saved: at their defaults a config's key is what it
    was before they existed (the spring default's key below was read off a run saved before them)."""
    Config = hnn.load_task("spring", "train").Config
    assert Config().key() == "cbac7a2b"
    assert "init" not in Config().identity() and "derivative_loss" not in Config().identity()
    for field, value in (("init", "zero_bias"), ("init", "lnn"), ("derivative_loss", "l1")):
        other = Config(**{field: value})
        assert other.identity()[field] == value and other.key() != Config().key()


def test_help_and_flag_errors_answer_before_torch_loads():
    """``--help`` and a bad flag load no torch, scipy, matplotlib or gymnasium (timings: not here)."""
    heavy = ("torch", "scipy", "matplotlib", "gymnasium")
    code = ("import runpy, sys\nsys.argv = [sys.argv[1], *sys.argv[2:]]\ntry:\n    runpy.run_path(sys.argv[0], "
            "run_name='__main__')\nexcept SystemExit:\n    pass\nprint(sorted(m for m in %r if m in sys.modules))" % (heavy,))
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    for task in hnn.available_tasks():
        for argv in (["--help"], ["--total_step", "3"]):
            out = subprocess.run([sys.executable, "-c", code, f"experiment-{task}/train.py", *argv], cwd=REPO,
                                 env=env, capture_output=True, text=True, timeout=120)
            assert out.stdout.splitlines()[-1] == "[]", (task, argv, out.stdout[-300:], out.stderr[-300:])


def test_main_raises_for_programs_and_debug_does_not_change_the_run(tmp_path):
    with pytest.raises(FileNotFoundError, match=str(tmp_path)):
        hnn.load_task("real", "train").main(["--data_dir", str(tmp_path)])
    trainer = hnn.load_task("spring", "train")
    argv = ["--total_steps", "0", "--save_dir", str(tmp_path)]
    run = trainer.main(argv)
    assert find_run(hnn.cli.parse(trainer.Config, argv + ["--debug"])) == run


# ----------------------------------------------------------------------------------------------
# the scripts, as a user runs them


def _run(script: str, *argv: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, f"experiment-{script}/train.py", *argv], cwd=REPO, env=env, check=False,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("task, argv, names", [
    ("spring", ["--nonlinearity", "foo"], ["'foo'"]),
    ("spring", ["--input_dim", "3"], ["--input_dim: 3 does not", "width 2"]),
    ("pixels", ["--latent_dim", "3"], ["--latent_dim", "'3'"]),
])
def test_script_bad_flag(task, argv, names):
    out = _run(task, *argv)
    assert out.returncode == 2
    _assert_one_error(out.stderr, *names)


def test_script_missing_real_data(tmp_path):
    out = _run("real", "--data_dir", str(tmp_path), "--save_dir", str(tmp_path))
    assert out.returncode == 2
    line = _assert_one_error(out.stderr, str(tmp_path), "real_pend_h_1.txt", "--data_dir")
    assert out.stderr.splitlines() == [line]


def test_script_missing_real_data_debug_shows_the_traceback(tmp_path):
    out = _run("real", "--data_dir", str(tmp_path), "--save_dir", str(tmp_path), "--debug")
    assert out.returncode not in (0, 2)
    assert "Traceback" in out.stderr and "FileNotFoundError" in out.stderr
    assert not _error_lines(out.stderr)


def test_script_prints_the_saved_run(tmp_path):
    out = _run("spring", "--total_steps", "2", "--save_dir", str(tmp_path))
    assert out.returncode == 0, out.stderr
    folder = hnn.runs.run_dir(hnn.cli.parse(hnn.load_task("spring", "train").Config, ["--total_steps", "2", "--save_dir",
                                                                                 str(tmp_path)]))
    assert folder.name.startswith("spring-hnn-seed0-") and folder.is_dir()
    assert out.stdout.splitlines()[-1] == f"saved the run to {folder}"
    assert (folder / "model.tar").exists()


@pytest.mark.parametrize("where, names", [
    ("file", ["--save_dir", "is a file", "pass a folder"]),
    ("unwritable", ["--save_dir", "/proc/x", "pass a folder you can write"]),
])
def test_script_checks_save_dir_before_training(where, names, tmp_path):
    target = tmp_path / "a-file" if where == "file" else Path("/proc/x")
    if where == "file":
        target.write_text("not a folder")
    out = _run("spring", "--total_steps", "100000", "--save_dir", str(target))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    _assert_one_error(out.stderr, *names)


def test_a_run_with_other_flags_keeps_the_first_and_a_copied_folder_is_reused(tmp_path):
    trainer = hnn.load_task("spring", "train")
    first = trainer.main(["--total_steps", "3", "--save_dir", str(tmp_path / "a")])
    second = trainer.main(["--total_steps", "2", "--hidden_dim", "16", "--save_dir", str(tmp_path / "a")])
    assert first != second and hnn.load_run(first)[1]["total_steps"] == 3 and hnn.load_run(second)[1]["hidden_dim"] == 16
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    copied = find_run(hnn.cli.parse(trainer.Config, ["--total_steps", "3", "--save_dir", str(tmp_path / "b")]))
    assert copied == tmp_path / "b" / first.name        # save_dir is where a run lies, not what it is


def test_a_config_runs_from_python_with_no_argv(tmp_path):
    Config = hnn.load_task("spring", "train").Config
    config = Config(total_steps=2, hidden_dim=8, model="baseline", save_dir=str(tmp_path))
    run = hnn.run_experiment(config)
    assert run == hnn.runs.run_dir(config) == hnn.runs.run_dir(hnn.cli.parse(Config, [
        "--total_steps", "2", "--hidden_dim", "8", "--baseline", "--save_dir", str(tmp_path)]))
    assert hnn.load_run(run)[1]["kind"] == "baseline"
    with pytest.raises(ValueError, match="hidden_dim=0: must be an integer >= 1"):
        hnn.run_experiment(Config(hidden_dim=0, save_dir=str(tmp_path)))
    with pytest.raises(ValueError, match="model='sideways': choose one of hnn, baseline"):
        hnn.run_experiment(Config(model="sideways", save_dir=str(tmp_path)))


def test_every_config_field_is_a_documented_flag():
    for task in hnn.available_tasks():
        Config = hnn.load_task(task, "train").Config
        text = hnn.cli.make_parser(Config).format_help()
        for field in dataclasses.fields(Config):
            assert f"--{field.name}" in text, (task, field.name)
            assert hnn.cli.field_meta(Config, field.name).get("help"), (task, field.name)
