"""Everything reads the registries: a solver registered with hnn.register_solver, and a toy model
kind (one module, here the class ``_Scaled``, plus one row of hnn.MODEL_KINDS carrying its prose) reach
``--model`` and its help, a run and ``hnn.load_run``, both studies' outputs, the peers table and the
pages' lists of kinds, with no list anywhere touched (a new solver or kind is one place)."""
import pytest
import torch

import hnn
from hnn_analysis import pages
from hnn_analysis.chains import peer_plan, peers
from hnn_analysis.scenes import scene_metrics, scene_tables, scene_common
from hnn_analysis.integrator_study import speed_measure


class _Euler(hnn.integrators.fixed_step.Stepper):
    """Explicit Euler, ``x + h f(x)``: order 1, not symplectic (a toy solver)."""

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        self.nfev += 1
        return x + h * self.f(x)


class _Scaled(hnn.Model):
    """A toy model kind: the HNN's field times a learned scalar (its H is still conserved)."""
    conservative = True
    takes = hnn.interface.UNIT_MASS          # like the HNN, it reads observed [q, qdot] as [q, p]

    def __init__(self, inner):
        super().__init__()
        self.inner, self.scale = inner, torch.nn.Parameter(torch.ones(()))
        self.input_dim = inner.input_dim

    def hamiltonian(self, x):
        return self.inner.hamiltonian(x)

    def time_derivative(self, x, t=None):
        return self.scale * self.inner.time_derivative(x)


_SCALED_DOC = hnn.kind_docs.KindDoc(line="the HNN's field times one learned scalar (a toy)", assumes="what the HNN does",
                                    coordinates="canonical x = [q, p]", integrator="`midpoint`", when="never: a test")


@pytest.fixture
def toys(monkeypatch):
    """'toy-euler' in hnn.SOLVERS and the row 'scaled' in hnn.MODEL_KINDS, for one test."""
    # the class named as "module:Class", imported on first build, as a kind of another package would be
    monkeypatch.setitem(hnn.MODEL_KINDS, "scaled", hnn.kinds.ModelKind(
        f"{_Scaled.__module__}:_Scaled", lambda cls, spec: cls(hnn.build_model(spec.input_dim, spec.hidden_dim,
                                                                               spec.nonlinearity)),
        color="tab:olive", doc=_SCALED_DOC))
    hnn.register_solver(hnn.integrators.solvers.fixed_step_solver("toy-euler", _Euler, order=1))
    yield
    del hnn.SOLVERS["toy-euler"]


def test_both_studies_try_every_registered_solver_that_applies(toys):
    reads_h = {name for name, solver in hnn.SOLVERS.items() if solver.needs_hamiltonian}
    assert reads_h == {"discrete_gradient"}
    for separable in (False, True):
        for energy in (False, True):      # a field that carries its H gets the solvers that read it
            methods = {options["method"] for options in scene_metrics.settings_ladder((0.1, 0.05), separable, True,
                                                                                       energy)}
            expected = set(hnn.SOLVERS) - ({"leapfrog"} if not separable else set()) - (set() if energy else reads_h)
            assert methods == expected, (separable, energy)
        labels = {label for label, _ in speed_measure._settings("model", True, (0.1, 0.05), separable)}
        assert "toy-euler" in labels and ("leapfrog" in labels) == separable


def _untrained_run(task: str, kind: str, runs) -> None:
    """A saved run of ``task``'s default config of kind ``kind``, untrained (the studies only roll it out)."""
    config = hnn.tasks.task_config(task, {"model": kind, "seed": 0, "save_dir": str(runs)})
    saved = {**config.to_dict(), "kind": config.kind, "dataset_cache_key": None}
    torch.manual_seed(0)
    metrics = {"train_loss": 0.1, "train_loss_se": 0.0, "test_loss": 0.1, "test_loss_se": 0.0, "train_seconds": 0.0}
    hnn.runs.save_run(hnn.runs.run_dir(config), hnn.runs.model_from_args(saved), saved, metrics)


def test_the_integrator_study_measures_a_registered_kind_with_a_registered_solver(toys, tmp_path, monkeypatch):
    # a small grid, to keep the test quick: two start states, one tolerance, two steps
    spring = speed_measure.study_settings("spring")
    monkeypatch.setattr(speed_measure, "study_settings", lambda task: {**spring, "batch": 2, "dts": (0.1, 0.05)})
    monkeypatch.setattr(speed_measure, "QUICK_RTOLS", (1e-6,))
    # a learned map beside them has no field for the solvers: left to docs/maps.md, not a crash of the study
    for kind in ("hnn", "baseline", "scaled", "g_sympnet"):
        _untrained_run("spring", kind, tmp_path)
    notes = []
    rows = speed_measure.measure_task("spring", tmp_path, quick=True, repeats=1, notes=notes)
    measured = {(row["model"], row["method"]) for row in rows if row["status"] == "ok"}
    assert {("scaled", "toy-euler"), ("true", "toy-euler"), ("hnn", "toy-euler"), ("scaled", "midpoint")} <= measured
    assert "g_sympnet" not in {row["model"] for row in rows}
    assert not notes


def test_the_scene_study_measures_a_registered_kind_with_a_registered_solver(toys, tmp_path):
    assert "scaled" in scene_common.kinds() and scene_tables.color("scaled") == "tab:olive"
    _untrained_run("spring", "scaled", tmp_path)
    run = hnn.runs.find_run(hnn.tasks.task_config("spring", {"model": "scaled", "save_dir": str(tmp_path)}))
    scene = scene_common.Scene("spring", quick=True)
    measured = scene.measure("scaled", run, protocols=False)
    assert measured["rollout"]["error"] > 0
    speed = scene_common.speed_study(scene, "scaled", hnn.load_run(run)[0], quick=True)
    assert "toy-euler" in {row["options"]["method"] for row in speed["rows"]}
    assert "drift" in (speed["fastest"] or {}) or speed["fastest"] is None     # a conservative kind: its drift


def test_a_new_rollout_metric_is_one_entry_and_the_scene_study_reports_it(toys, tmp_path, monkeypatch):
    monkeypatch.setitem(hnn.metrics.ROLLOUT_METRICS, "final_error", lambda err, t: float(err[:, -1].mean()))
    _untrained_run("spring", "scaled", tmp_path)
    run = hnn.runs.find_run(hnn.tasks.task_config("spring", {"model": "scaled", "save_dir": str(tmp_path)}))
    rollout = scene_common.Scene("spring", quick=True).measure("scaled", run, protocols=False)["rollout"]
    err = hnn.metrics.relative_error(torch.zeros(1, 3, 2), torch.ones(1, 3, 2))     # pred 0: e(t) = 1
    assert hnn.metrics.summarize_errors(err, torch.arange(3.0).numpy())["final_error"] == 1.0
    assert 0 < rollout["final_error"] <= 1 and rollout["error"] > 0


def test_a_new_kind_reaches_the_flags_a_run_load_run_and_the_peers_table(toys, tmp_path):
    trainer = hnn.load_task("spring", "train")
    help_text = " ".join(hnn.cli.make_parser(trainer.Config).format_help().split())
    assert f"scaled ({_SCALED_DOC.line})" in help_text          # a --model choice, with its row's line
    # the pages' lists: the README's line and docs/python.md's paragraph, from the row; both pages lack it
    assert f"- `scaled`: {_SCALED_DOC.line}." in pages.kinds_text("kinds")
    assert "**`scaled`**: the HNN's field" in pages.kinds_text("kinds-python")
    assert len(pages.declared_out_of_date()) == 2
    run = trainer.main(["--model", "scaled", "--total_steps", "3", "--hidden_dim", "8", "--save_dir", str(tmp_path)])
    model, saved, metrics = hnn.load_run(run)
    assert saved["kind"] == "scaled" and isinstance(model, _Scaled) and metrics["train_loss"] > 0
    # the peers table: the chain's observed [q, qdot] are read by the toy (as the HNN reads them)
    assert "scaled" in peer_plan.kinds()
    tiny = {"bobs": (1,), "fields": {"n_train": 4, "n_test": 2, "hidden_dim": 8, "total_steps": 2},
            "test_starts": 2, "lnn_starts": 0, "lnn_fields": {}, "kinds": ("hnn", "scaled")}
    results = peers.main(["--out", str(tmp_path / "peers")], settings=tiny)
    assert "ours: scaled" in (tmp_path / "peers" / "peers.md").read_text()
    entry = results["rows"]["chain1"]["scaled"]
    assert "blew_up" in entry or 0 < entry["median"] <= 1
