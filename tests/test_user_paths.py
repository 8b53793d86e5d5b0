"""The paths a user takes off the paper's (issue 78), each through the public door: a learned map built and
trained from Python as the commands build and train it (docs/maps.md's recipe), ``analysis/score.py`` on a
map's run, a folder and an unfinished run, the measured path's map pairs, errors in the caller's words, and
runs named by what they are."""
import json
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import hnn
from hnn.evaluation import float64_copy, quiet_rollout, rollout_errors
from hnn.metrics import path_errors
from hnn.models import GSympNet, HenonNet, LASympNet
from hnn.objectives.map import MapNotLearnedWarning, MapObjective, identity_errors
from hnn_analysis import score

REPO = Path(__file__).resolve().parent.parent


def _pend_train(argv):
    return hnn.load_task("pend", "train").main(argv)


@pytest.fixture(scope="module")
def map_run(tmp_path_factory):
    """A pendulum g_sympnet run of the command (a few steps: score.py's paths, not its accuracy, are tested)."""
    return Path(_pend_train(["--model", "g_sympnet", "--total_steps", "30", "--hidden_dim", "16",
                             "--save_dir", str(tmp_path_factory.mktemp("runs"))]))


# ----------------------------------------------------------------------------------------------
# 1. a map from Python is the command's


@pytest.mark.parametrize("cls, kind", [(GSympNet, "g_sympnet"), (LASympNet, "la_sympnet"), (HenonNet, "henon")])
def test_a_map_built_in_python_is_the_one_the_command_trains(cls, kind):
    # the command's model of the kind, from its config's defaults, against the class's own defaults
    config = hnn.tasks.task_config("pend", {"model": kind})
    commanded = hnn.kinds.model_from_spec(hnn.specs.run_specs(config).model)
    built = cls(2)
    assert [(n, tuple(p.shape)) for n, p in built.named_parameters()] == \
        [(n, tuple(p.shape)) for n, p in commanded.named_parameters()]
    activations = {getattr(m, "activation", None) for m in built.modules()} - {None}
    assert activations == {getattr(m, "activation", None) for m in commanded.modules()} - {None} == {"tanh"}


def _docs_recipe() -> str:
    text = (REPO / "docs" / "maps.md").read_text()
    return re.search(r"## Train a map on your own pairs.*?```python\n(.*?)```", text, re.S).group(1)


@pytest.mark.slow
def test_the_docs_recipe_trains_a_map_that_follows_the_true_pendulum():
    namespace: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("error", MapNotLearnedWarning)        # a map that learned: no warning
        exec(compile(_docs_recipe(), "docs/maps.md", "exec"), namespace)
    model, data = namespace["model"], namespace["data"]
    assert namespace["path"].shape == (1, 150, 2)
    # 10 time units from ten of the held-out starts, against the true pendulum (DOP853, rtol 1e-12)
    task = hnn.load_task("pend")
    t = model.dt * np.arange(int(10 / model.dt) + 1)
    x0 = torch.as_tensor(np.asarray(data["test_x"])[::len(data["t_eval"])][:10], dtype=torch.float64)
    truth = quiet_rollout(lambda x, t=None: task.dynamics(x), x0, t, method="dop853", rtol=1e-12, atol=1e-12)
    learned = rollout_errors(float64_copy(model), truth, t, options={})     # a map: its own steps
    identity = path_errors(truth[:, :1].expand_as(truth), truth, t)
    # a learned bound, set against the identity map (no learning: 0.53): the command's tanh map here 0.17 of
    # it (0.091), SympNets' sigmoid, the classes' default before, 0.74 (0.39), the noise floor of the data
    # (std 0.1 on every state) keeping any fit from reaching 0
    assert learned["error"] < identity["error"] / 3, (learned["error"], identity["error"])


def test_a_map_that_ends_no_better_than_the_identity_warns_with_the_fix():
    data = MapObjective().prepare(hnn.load_task("pend").get_dataset(seed=0))
    model = GSympNet(2, 8, 2, dt=float(data["dt"]))
    with torch.no_grad():        # the exact identity: every potential's gradient is 0, and so is the loss's
        for w in model.parameters():
            w.zero_()
    with pytest.warns(MapNotLearnedWarning, match=r"no\s+smaller than the identity map's.*tanh"):
        hnn.train(model, data["pairs"], data["pairs"], loss=MapObjective(dt=model.dt).loss_for(model),
                  total_steps=3, progress=False)


def test_a_map_that_learned_q_and_left_p_where_it_was_warns_naming_p():
    # the shears that move p held at 0 (an exact identity in p), those that move q trained: the whole state's
    # error is below the identity's (q's gain hides p's none), so only a judge of each half catches it
    data = MapObjective().prepare(hnn.load_task("pend").get_dataset(seed=0))
    model = GSympNet(2, 16, 2, dt=float(data["dt"]))
    for layer in model.layers:
        if layer.part == "p":
            for w in layer.parameters():
                w.requires_grad_(False).zero_()
    with pytest.warns(MapNotLearnedWarning, match=r"in p (\S+) against \1: it learned nothing of how p moves"):
        hnn.train(model, data["pairs"], data["pairs"], loss=MapObjective(dt=model.dt).loss_for(model),
                  total_steps=300, progress=False)
    error, identity = identity_errors(model, data["pairs"])
    assert error.mean() < identity.mean() and error[0] < identity[0] and error[1] == identity[1]


@pytest.mark.slow
@pytest.mark.parametrize("task", ["spring", "pend"])
def test_the_commands_default_map_learns_both_halves_without_a_warning(task, tmp_path):
    # the command's map (tanh, width 200, 4 layers, its steps): better than the identity in q and in p by a
    # wide margin (pend: 0.41 and 0.42 of the identity's error, the rest the data's noise), so no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error", MapNotLearnedWarning)
        run = hnn.load_task(task, "train").main(["--model", "g_sympnet", "--save_dir", str(tmp_path)])
    model = hnn.load_run(run)[0]
    data = MapObjective().prepare(hnn.load_task(task).get_dataset(seed=0))
    error, identity = identity_errors(model, data["pairs"])
    assert (error < identity).all(), (error, identity)


# ----------------------------------------------------------------------------------------------
# 2. score.py ends in a result or one error line


def test_score_plots_a_maps_energy_over_its_own_steps(map_run, tmp_path, capsys):
    out = tmp_path / "figures"
    score.main([str(map_run), "--plot", "--out", str(out)])
    drawn = {p.name for p in out.iterdir()}
    assert {"pend-energy-paper.png", "pend-energy-corrected.png", "score.json"} <= drawn, drawn
    assert not any(name.endswith(("fields.png", "integration.png")) for name in drawn)     # a map has no field
    assert json.loads((out / "score.json").read_text())["runs"][0]["kind"] == "g_sympnet"


def _unfinished_copy(run: Path, where: Path) -> Path:
    copy = where / run.name.replace("seed0", "seed9")
    shutil.copytree(run, copy)
    (copy / hnn.runs.COMPLETE).unlink()
    return copy


def test_an_unfinished_run_is_one_error_line_with_the_fix(map_run, tmp_path, capsys):
    unfinished = _unfinished_copy(map_run, tmp_path)
    with pytest.raises(SystemExit) as stop:
        score.main([str(unfinished)])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.count("\n") == 1 and err.startswith("error: ")
    assert "complete.json" in err and "train.py again" in err


def test_a_folder_is_scored_run_by_run_and_names_the_runs_that_fail(map_run, tmp_path, capsys):
    folder = tmp_path / "runs"
    shutil.copytree(map_run, folder / map_run.name)
    unfinished = _unfinished_copy(map_run, folder)
    with pytest.raises(SystemExit) as stop:
        score.main([str(folder), "--out", str(tmp_path / "out")])
    out, err = capsys.readouterr()
    assert stop.value.code == 1 and err.startswith("error: 1 of 2 runs not scored: " + unfinished.name)
    saved = json.loads((tmp_path / "out" / "score.json").read_text())
    assert [Path(r["run"]).name for r in saved["runs"]] == [map_run.name]       # the good one, after the bad one
    assert list(saved["not_scored"]) == [str(unfinished)]


# ----------------------------------------------------------------------------------------------
# 3. the measured path pairs a map's rows at the data's own step, whatever the units


def _oscillator_file(path: Path, seconds_per_unit: float) -> Path:
    """Two trials of H = (q^2 + p^2) / 2, every 0.05 s, the time column in units of ``seconds_per_unit``."""
    t = 0.05 * np.arange(200)
    rows = [(k, s / seconds_per_unit, a * np.cos(s), -a * np.sin(s)) for k, a in ((0, 1.0), (1, 1.5)) for s in t]
    np.savetxt(path, rows, delimiter=",", header="trial,t,x,px", comments="")
    return path


# t in seconds, in minutes and in milliseconds (whose dq/dt, 1e-3 of the seconds', lies outside --units auto's
# bounds: a map's loss reads no rate, so auto judges its states alone, hnn.units.sized_arrays)
@pytest.mark.parametrize("seconds_per_unit", [1.0, 60.0, 1e-3])
def test_a_measured_map_trains_on_pairs_at_the_files_own_step(tmp_path, seconds_per_unit):
    data = _oscillator_file(tmp_path / "osc.csv", seconds_per_unit)
    argv = ["--data", str(data), "--time", "t", "--q", "x", "--p", "px", "--trial", "trial"]
    run = hnn.load_task("measured", "train").main(argv + ["--model", "g_sympnet", "--total_steps", "5",
                                                          "--hidden_dim", "8", "--save_dir", str(tmp_path / "runs")])
    assert np.isfinite(json.loads((Path(run) / "metrics.json").read_text())["train_loss"])
    # each trial's training part and test part are rows at the file's step: every consecutive two a pair
    dataset = MapObjective().prepare(hnn.load_task("measured").get_dataset(str(data), "t", "x", p="px", trial="trial"))
    assert len(dataset["pairs"]) == len(dataset["x"]) - 2 and len(dataset["test_pairs"]) == len(dataset["test_x"]) - 2


def test_a_measured_map_is_the_same_map_whatever_the_unit_of_the_files_time(tmp_path):
    # the file in seconds and in milliseconds holds the same states at the same samples: a map fits one state to
    # the next and reads no time, so --units auto (the default) trains the same map on both, each at its file's step
    runs = {}
    for seconds_per_unit in (1.0, 1e-3):
        data = _oscillator_file(tmp_path / f"osc-{seconds_per_unit:g}.csv", seconds_per_unit)
        runs[seconds_per_unit] = Path(hnn.load_task("measured", "train").main(
            ["--data", str(data), "--time", "t", "--q", "x", "--p", "px", "--trial", "trial", "--model", "g_sympnet",
             "--total_steps", "20", "--hidden_dim", "8", "--save_dir", str(tmp_path / "runs")]))
    metrics = {k: json.loads((run / "metrics.json").read_text()) for k, run in runs.items()}
    # the same rows and seed through the same arithmetic in one process: the same bits, not a tolerance
    assert metrics[1.0]["train_loss"] == metrics[1e-3]["train_loss"]
    assert metrics[1.0]["test_loss"] == metrics[1e-3]["test_loss"]
    for seconds_per_unit, run in runs.items():      # its step, back in the file's time: 0.05 s, or 50 ms
        step = json.loads((run / "args.json").read_text())["dt"] * json.loads((run / "scale.json").read_text())["tau"]
        assert step == pytest.approx(0.05 / seconds_per_unit, rel=1e-12)


def test_score_reads_a_measured_map_at_its_own_steps_the_same_in_seconds_and_milliseconds(tmp_path, capsys):
    # the held-out horizon is a whole number of the file's steps, which the map was trained at: score.py steps
    # it there (it has no field to integrate to an arbitrary time); the same map on the same states in seconds
    # and in milliseconds predicts the same positions, so both files' errors are one number
    errors = {}
    for seconds_per_unit in (1.0, 1e-3):
        data = _oscillator_file(tmp_path / f"osc-{seconds_per_unit:g}.csv", seconds_per_unit)
        run = hnn.load_task("measured", "train").main(
            ["--data", str(data), "--time", "t", "--q", "x", "--p", "px", "--trial", "trial", "--model", "g_sympnet",
             "--total_steps", "20", "--hidden_dim", "8", "--save_dir", str(tmp_path / f"runs{seconds_per_unit:g}")])
        [scored] = score.main([str(run), "--out", str(tmp_path / f"score{seconds_per_unit:g}")])
        assert "next-state MSE" in capsys.readouterr().out
        errors[seconds_per_unit] = scored["prediction_error"]
        assert scored["horizon"] * seconds_per_unit == pytest.approx(0.295, rel=1e-9)   # a tenth of a 60-row tail
    assert errors[1.0]["starts"] == errors[1e-3]["starts"] > 0
    assert errors[1.0]["median"] == pytest.approx(errors[1e-3]["median"], rel=1e-9)


def test_a_dataset_with_no_pair_one_step_apart_is_an_error_naming_it():
    x = np.zeros((10, 2))
    dataset = {"x": x, "test_x": x, "t": 0.3 * np.arange(10), "test_t": 0.3 * np.arange(10), "dt": 0.1}
    with pytest.raises(ValueError, match=r"no pairs and no test_pairs .* one step 0.1 apart"):
        MapObjective().prepare(dataset)


# ----------------------------------------------------------------------------------------------
# 4. errors in the caller's words


def test_rollout_errors_of_a_map_rolls_it_out_and_a_method_passed_is_named():
    model = GSympNet(2, 8, 2, dt=0.1).double()
    t = 0.1 * np.arange(20)
    truth = quiet_rollout(model, torch.tensor([[0.5, 0.0]], dtype=torch.float64), t)
    scored = rollout_errors(model, truth, t)        # no method asked: the map steps itself
    # the same map's steps both times, whose summation order may differ (the rollout's numpy kernel or torch):
    # round-off of 20 steps of float64, far below 1e-12
    assert scored["error"] < 1e-12 and scored["blew_up"] == 0
    with pytest.raises(ValueError, match="drop method='rk4'"):
        hnn.rollout(model, truth[:, 0], t, method="rk4")


def test_a_misspelled_flag_is_answered_with_the_flag_its_words_name(capsys):
    for flag, meant in (("--fit-type", "--fit"), ("--total-steps", "--total_steps"), ("--learn_rates", "--learn_rate")):
        with pytest.raises(SystemExit):
            _pend_train([flag, "1"])
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"{flag}: did you mean {meant}?" in err, err


# ----------------------------------------------------------------------------------------------
# 5. runs named by what they are


def test_a_least_squares_run_is_named_by_its_fit_and_scored_and_drawn_so(map_run, tmp_path, capsys, monkeypatch):
    from hnn_analysis.paper import figures, registry
    runs = {fit: Path(_pend_train(["--fit", fit, "--hidden_dim", "40", "--save_dir", str(tmp_path / "runs")]))
            for fit in ("library", "swim")}
    assert runs["library"].name.startswith("pend-hnn+library-seed0-")
    assert runs["swim"].name.startswith("pend-hnn+swim-seed0-")
    adam = hnn.runs.run_dir(hnn.cli.parse(hnn.load_task("pend", "train").Config, ["--save_dir", str(tmp_path)]))
    assert adam.name.startswith("pend-hnn-seed0-")         # the paper's runs keep their names
    labels, save = set(), figures.save_figure

    def read_labels(fig, path):         # what each figure calls its lines, then the figure saved as ever
        labels.update(label for ax in fig.axes for label in ax.get_legend_handles_labels()[1])
        return save(fig, path)
    monkeypatch.setattr(figures, "save_figure", read_labels)
    # one figure names the model enough (the energy figures of 15 panels each cost 10 s: the map's test draws them)
    monkeypatch.setattr(registry, "RUN_FIGURES", ("integration",))
    folder = tmp_path / "scored"        # the library run beside a map's (whose figure is its energy alone)
    for run in (runs["library"], map_run):
        shutil.copytree(run, folder / run.name)
    score.main([str(folder), "--plot", "--out", str(tmp_path / "out")])
    table = capsys.readouterr().out
    assert re.search(r"\| pend-hnn\+library-seed0-\w+ \| pend \| hnn\+library \|", table)
    assert re.search(r"\| pend-g_sympnet-seed0-\w+ \| pend \| g_sympnet \|", table)
    assert "Hamiltonian NN (library fit)" in labels, labels
