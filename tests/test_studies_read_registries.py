"""The integrator study and the scene study measure what the registries hold: a solver registered
with hnn.register_solver and a model kind registered with hnn.register_model_kind show up in both
studies' outputs, with no list in the studies touched (a new solver or kind is one place)."""
import pytest
import torch

import hnn
from hnn_analysis.scenes import scene_metrics, scene_report, scene_study
from hnn_analysis.speed import speed_accuracy


class _Euler(hnn.fixed_step.Stepper):
    """Explicit Euler, ``x + h f(x)``: order 1, not symplectic (a toy solver)."""

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        self.nfev += 1
        return x + h * self.f(x)


class _Scaled(torch.nn.Module):
    """A toy model kind: the HNN's field times a learned scalar."""

    def __init__(self, inner):
        super().__init__()
        self.inner, self.scale = inner, torch.nn.Parameter(torch.ones(()))

    def hamiltonian(self, x):
        return self.inner.hamiltonian(x)

    def time_derivative(self, x):
        return self.scale * self.inner.time_derivative(x)


@pytest.fixture
def toys(monkeypatch):
    """'toy-euler' in hnn.SOLVERS and 'scaled' in hnn.MODEL_KINDS, for one test."""
    monkeypatch.setattr(hnn.objectives, "MODEL_KINDS", dict(hnn.objectives.MODEL_KINDS))
    monkeypatch.setattr(hnn, "MODEL_KINDS", hnn.objectives.MODEL_KINDS)
    hnn.register_model_kind("scaled", hnn.DerivativeObjective, lambda args: _Scaled(
        hnn.build_model(args["input_dim"], args["hidden_dim"], args["nonlinearity"])), conservative=True,
        color="tab:olive")
    hnn.register_solver(hnn.solvers.fixed_step_solver("toy-euler", _Euler, order=1))
    yield
    del hnn.SOLVERS["toy-euler"]


def test_both_studies_try_every_registered_solver_that_applies(toys):
    for separable in (False, True):
        methods = {options["method"] for options in scene_metrics.settings_ladder((0.1, 0.05), separable, True)}
        assert methods == set(hnn.SOLVERS) - ({"leapfrog"} if not separable else set()), separable
        labels = {label for label, _ in speed_accuracy._settings("model", True, (0.1, 0.05), separable)}
        assert "toy-euler" in labels and ("leapfrog" in labels) == separable


def _untrained_run(task: str, label: str, runs) -> None:
    """A saved run of ``task``'s default config of kind ``label``, untrained (the studies only roll it out)."""
    config = hnn.tasks.task_config(task, {"model": label, "seed": 0, "save_dir": str(runs)})
    saved = {**config.to_dict(), "kind": config.kind, "dataset_cache_key": None}
    torch.manual_seed(0)
    metrics = {"train_loss": 0.1, "train_loss_se": 0.0, "test_loss": 0.1, "test_loss_se": 0.0, "train_seconds": 0.0}
    hnn.save_run(hnn.run_dir(config), hnn.runs.model_from_args(saved), saved, metrics)


def test_the_integrator_study_measures_a_registered_kind_with_a_registered_solver(toys, tmp_path, monkeypatch):
    # a small grid, to keep the test quick: two start states, one tolerance, two steps
    monkeypatch.setitem(speed_accuracy.TASKS, "spring", {**speed_accuracy.TASKS["spring"], "batch": 2,
                                                         "dts": (0.1, 0.05)})
    monkeypatch.setattr(speed_accuracy, "QUICK_RTOLS", (1e-6,))
    for label in ("hnn", "baseline", "scaled"):
        _untrained_run("spring", label, tmp_path)
    notes = []
    rows = speed_accuracy.measure_task("spring", tmp_path, quick=True, repeats=1, notes=notes)
    measured = {(row["model"], row["method"]) for row in rows if row["status"] == "ok"}
    assert {("scaled", "toy-euler"), ("true", "toy-euler"), ("hnn", "toy-euler"), ("scaled", "midpoint")} <= measured
    assert not notes


def test_the_scene_study_measures_a_registered_kind_with_a_registered_solver(toys, tmp_path):
    assert "scaled" in scene_study.rungs() and scene_report.color("scaled") == "tab:olive"
    _untrained_run("spring", "scaled", tmp_path)
    run = hnn.find_run(hnn.tasks.task_config("spring", {"model": "scaled", "save_dir": str(tmp_path)}))
    scene = scene_study.Scene("spring", quick=True)
    measured = scene.measure("scaled", run, protocols=False)
    assert measured["rollout"]["error"] > 0
    speed = scene_study.speed_study(scene, "scaled", hnn.load_run(run)[0], quick=True)
    assert "toy-euler" in {row["options"]["method"] for row in speed["rows"]}
    assert "drift" in (speed["fastest"] or {}) or speed["fastest"] is None     # a conservative kind: its drift


def test_a_new_rollout_metric_is_one_entry_and_the_scene_study_reports_it(toys, tmp_path, monkeypatch):
    monkeypatch.setitem(hnn.metrics.ROLLOUT_METRICS, "final_error", lambda err, t: float(err[:, -1].mean()))
    _untrained_run("spring", "scaled", tmp_path)
    run = hnn.find_run(hnn.tasks.task_config("spring", {"model": "scaled", "save_dir": str(tmp_path)}))
    rollout = scene_study.Scene("spring", quick=True).measure("scaled", run, protocols=False)["rollout"]
    err = hnn.metrics.relative_error(torch.zeros(1, 3, 2), torch.ones(1, 3, 2))     # pred 0: e(t) = 1
    assert hnn.metrics.summarize_errors(err, torch.arange(3.0).numpy())["final_error"] == 1.0
    assert 0 < rollout["final_error"] <= 1 and rollout["error"] > 0
