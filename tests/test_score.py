"""analysis/score.py: a saved run scored as the scene study measures it, its figures from the run alone, and
its input checked before torch loads."""
import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

import hnn
from hnn_analysis import score
from hnn_analysis.scenes import scene_common, scene_measure

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def spring_run(tmp_path_factory):
    save_dir = tmp_path_factory.mktemp("runs")
    config = hnn.tasks.task_config("spring", {"total_steps": 60, "hidden_dim": 32, "save_dir": str(save_dir)})
    return hnn.run_experiment(config)


def test_a_run_scores_the_numbers_the_scene_study_measures_of_it(spring_run, capsys):
    # the study's own measurement of the run, as its cards read it: grouped energy protocols, its rollout
    study = scene_measure.measure_models(scene_common.Scene("spring", quick=False), {"run": ("hnn", spring_run)})["run"]
    scored = score.score_run(spring_run)
    assert scored["task"] == "spring" and scored["kind"] == "hnn"
    assert scored["test_loss"] == study["test_loss"]
    for protocol in ("paper", "corrected"):
        assert scored[f"energy_mse_{protocol}"] == pytest.approx(study[f"energy_mse_{protocol}"], rel=1e-9)
    for key in ("error", "valid_time", "horizon"):
        assert scored["rollout"][key] == pytest.approx(study["rollout"][key], rel=1e-9)
    assert scored["rollout"]["horizon"] == 10 * hnn.task_spec("spring").scene_study["T"]    # the cards' horizon
    # the command prints the same numbers, each protocol by name
    score.main([str(spring_run)])
    out = capsys.readouterr().out
    assert f"energy MSE, corrected protocol: {scored['energy_mse_corrected'][0]:.3g}" in out
    assert f"rollout error {scored['rollout']['error']:.3g} (the scene cards' protocol)" in out


def test_plot_draws_the_field_a_path_against_the_truth_and_the_energy_from_the_run_alone(spring_run, tmp_path):
    score.main([str(spring_run), "--plot", "--out", str(tmp_path)])
    drawn = {p.name for p in tmp_path.iterdir()}
    assert {"spring-fields.png", "spring-integration.png", "spring-energy-paper.png",
            "spring-energy-corrected.png"} <= drawn, drawn


def test_a_runs_task_is_read_off_its_settings_and_name():
    spring = hnn.tasks.task_config("spring", {"name": "spring-w16-f0.25"}).to_dict()
    assert score.task_of(spring) == "spring"
    assert score.task_of(hnn.tasks.task_config("3body", {"name": "3body-clean"}).to_dict()) == "3body"
    with pytest.raises(ValueError, match="cannot tell the task"):
        score.task_of({**spring, "name": "mine"})       # spring, pend and real share every field


@pytest.mark.parametrize("argv, words", [
    (["analysis/score.py", "no/such/run"], "does not exist"),
    (["analysis/reproduce.py", "--quick", "--tasks", "sprin"], "no such task here"),
    (["analysis/reproduce.py", "--quik"], "did you mean --quick"),
    (["analysis/scene_study.py", "--data", "no/such/file.csv", "--q", "x", "--v", "v"], "no/such/file.csv"),
    (["analysis/scene_study.py", "--data", "experiment-measured/systems/real_linear_h_1.txt", "--q", "xx",
      "--v", "v"], "did you mean 'x'"),
])
def test_input_errors_answer_in_one_line_before_torch_loads(argv, words):
    code = ("import runpy, sys\nsys.argv = sys.argv[1:]\ntry:\n    runpy.run_path(sys.argv[0], run_name='__main__')\n"
            "except SystemExit as e:\n    print('exit', e.code)\nprint('torch' in sys.modules)")
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", code, *argv], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.stdout.splitlines()[-2:] == ["exit 2", "False"], (done.stdout[-500:], done.stderr[-500:])
    errors = done.stderr.strip().splitlines()
    assert len(errors) == 1 and errors[0].startswith("error: ") and words in errors[0], done.stderr


@pytest.mark.parametrize("module", ["hnn_analysis.paper.reproduce", "hnn_analysis.scenes.scene_study",
                                    "hnn_analysis.chains.peers", "hnn_analysis.stress", "hnn_analysis.arm",
                                    "hnn_analysis.score", "hnn_analysis.readme", "hnn_analysis.chains.dgnet",
                                    "hnn_analysis.integrator_study.speed_accuracy",
                                    "hnn_analysis.integrator_study.energy_drift",
                                    "hnn_analysis.integrator_study.tolerances",
                                    "hnn_analysis.benchmarks.quick_budgets", "hnn_analysis.benchmarks.benchmark"])
def test_a_misspelled_flag_is_one_error_line_on_every_command(module, capsys):
    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as done:
        main(["--updat-docs"])
    err = capsys.readouterr().err.splitlines()
    assert done.value.code == 2 and len(err) == 1 and err[0].startswith("error: "), err
