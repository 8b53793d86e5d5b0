"""A task is one folder: the package finds it, reads its task.py, and reproduce.py runs it; the
package and the analysis name no task (tests/test_layers.py holds their imports free of circles)."""
import ast
import json
import textwrap
from pathlib import Path

import pytest

import hnn
from hnn_analysis.paper import reproduce

REPO = Path(hnn.__file__).resolve().parent.parent

# a task that is not in the paper: the 1-D harmonic oscillator H = (q^2 + p^2) / 2, its period 2 pi
TOY = {
    "data.py": '''
        """The toy system: H, its true dynamics and its dataset, nothing else."""
        import torch

        from hnn.datasets import ring_dataset


        def hamiltonian(x):
            return (x[..., 0] ** 2 + x[..., 1] ** 2) / 2


        def dynamics(x):
            return torch.stack([x[..., 1], -x[..., 0]], dim=-1)


        def get_dataset(seed=0, samples=20):
            return ring_dataset(dynamics, seed, samples, (0.0, 3.0), 10, (0.1, 1.0), 0.1)
        ''',
    "train.py": '''
        """Train the toy: its config (defaults, one field of its own, its dataset), the shared runner."""
        from dataclasses import dataclass
        from typing import ClassVar

        import hnn
        from hnn.settings import setting


        @dataclass
        class Config(hnn.RunConfig):
            """A toy oscillator."""
            name: str = "toy"
            save_dir: str = "."
            samples: int = setting(20, "trajectories in the dataset", parse=hnn.settings.int_at_least(2))
            DATASET_FIELDS: ClassVar[tuple] = ("seed", "samples")

            def dataset(self):
                return hnn.load_task("toy").get_dataset(seed=self.seed, samples=self.samples)


        def main(argv=None):
            return hnn.run_experiment(hnn.cli.parse(Config, argv))
        ''',
    "task.py": '''
        """The toy as reproduce.py sees it."""
        import hnn

        TASK = hnn.TaskSpec(
            order=1,
            protocols={"paper": hnn.EnergyProtocol("paper", t_span=(0.0, 5.0), num_points=20, num_trials=5)},
            figures=("energy", "fields"),
            figure_settings={"x0": (1.0, 0.0),
                             "fields": {"lim": 1.2, "gridsize": 5, "t_span": (0.0, 6.0), "num_points": 60}},
        )
        ''',
}


def _write_task(root: Path, name: str, files: dict) -> None:
    folder = root / f"experiment-{name}"
    folder.mkdir(parents=True)
    for filename, text in files.items():
        (folder / filename).write_text(textwrap.dedent(text).lstrip())


def test_a_new_task_is_one_folder_that_reproduce_runs(tmp_path, monkeypatch):
    _write_task(tmp_path / "repo", "toy", TOY)
    monkeypatch.setenv("HNN_REPO", str(tmp_path / "repo"))
    assert hnn.available_tasks() == ["toy"] and list(hnn.PROTOCOLS) == ["toy"] and "toy" not in hnn.tasks.PAPER
    out = tmp_path / "out"
    results = reproduce.main(["--quick", "--steps", "5", "--tasks", "toy", "--out", str(out)])
    row = results["tasks"]["toy"]
    assert set(row["protocols"]) == {"paper"} and row["hnn"]["energy_mse_paper"][0] > 0
    table = (out / "tables.md").read_text()
    assert "| toy | hnn | n/a |" in table and "| toy | baseline | n/a |" in table      # no paper numbers
    for name in ("toy-energy-paper.png", "toy-fields.png"):
        assert (out / "figures" / name).stat().st_size > 10_000, name
    [run] = (out / "runs").glob("toy-hnn-seed0-*")
    saved = json.loads((run / "args.json").read_text())
    assert saved["model"] == "hnn" and saved["dataset_cache_key"] is None and saved["total_steps"] == 5
    # its own field is a flag and a config field: --samples 10 trains on 10 trajectories in another folder
    config = hnn.cli.parse(hnn.load_task("toy", "train").Config, ["--samples", "10", "--total_steps", "1",
                                                                 "--save_dir", str(out / "runs")])
    assert config.samples == 10 and hnn.runs.run_dir(config) != run
    assert len(config.dataset()["x"]) == len(hnn.tasks.run_dataset("toy", saved)["x"]) // 2


def test_tasks_are_found_by_folder_in_their_declared_order(tmp_path, monkeypatch):
    for name, order in (("zeta", 1), ("alpha", None), ("beta", 1), ("gamma", 0.5)):
        _write_task(tmp_path, name, {"data.py": "", **({"task.py": f"import hnn\nTASK = hnn.TaskSpec(order={order})\n"}
                                                       if order is not None else {})})
    (tmp_path / "experiment-notes").mkdir()                  # no data.py: not a task
    monkeypatch.setenv("HNN_REPO", str(tmp_path))
    assert hnn.available_tasks() == ["gamma", "beta", "zeta", "alpha"]
    assert hnn.task_spec("alpha") == hnn.TaskSpec()          # no task.py: the default
    assert hnn.task_spec("alpha").figures == ("energy",) and not hnn.task_spec("alpha").protocols
    assert not dict(hnn.PROTOCOLS) and not dict(hnn.tasks.PAPER)
    with pytest.raises(ValueError, match="unknown task 'notes'"):
        hnn.task_spec("notes")



def test_a_tasks_data_module_is_checked_against_what_its_protocols_need(tmp_path, monkeypatch):
    """A task whose box protocol integrates the truth but whose data.py has no dynamics is named when it loads,
    not deep in a study; one without protocols needs only get_dataset."""
    lacking = {**TOY, "data.py": TOY["data.py"].replace("def dynamics(x):", "def _dynamics(x):").replace(
        "ring_dataset(dynamics,", "ring_dataset(_dynamics,")}
    _write_task(tmp_path, "toy", lacking)
    _write_task(tmp_path, "bare", {"data.py": "def get_dataset(seed=0):\n    return {}\n"})
    monkeypatch.setenv("HNN_REPO", str(tmp_path))
    with pytest.raises(TypeError, match=r"experiment-toy/data.py lacks dynamics \(its protocol 'paper' integrates"):
        hnn.load_task("toy")
    with pytest.raises(TypeError, match="lacks dynamics"):       # not cached half-checked: the second load says it too
        hnn.load_task("toy")
    assert hnn.load_task("bare").get_dataset() == {}

def test_protocols_and_paper_numbers_are_read_only_views_of_the_task_files():
    spec = hnn.task_spec("spring")
    assert hnn.PROTOCOLS["spring"]["paper"] is spec.protocols["paper"] is hnn.tasks.get_protocol("spring")
    assert hnn.tasks.PAPER["spring"]["test_loss"]["hnn"] == (3.5928e-02, 1.8328e-03)
    assert list(hnn.tasks.PAPER) == hnn.tasks.paper_tasks()
    # the paper's tasks, and the scenes of bodies with their one protocol of their own (no paper numbers)
    assert set(hnn.PROTOCOLS) == set(hnn.tasks.paper_tasks()) | {"gravity", "lattice", "lj"}
    assert all(set(hnn.PROTOCOLS[task]) == {"corrected"} and task not in hnn.tasks.PAPER
               for task in ("gravity", "lattice", "lj"))
    # the chain is a task (it trains and loads) but not the paper's: reproduce.py leaves it out
    assert "chain" in hnn.available_tasks() and "chain" not in hnn.tasks.paper_tasks()
    with pytest.raises(TypeError):
        hnn.PROTOCOLS["spring"]["paper"] = None
    with pytest.raises(ValueError, match="no energy protocol 'corrected' for task '2body'"):
        hnn.tasks.get_protocol("2body", "corrected")
    assert hnn.tasks.PROTOCOLS.get("nosuch") is None and "nosuch" not in hnn.tasks.PAPER


def _code_strings(path: Path) -> list[str]:
    """Every string constant of a module that is not a docstring."""
    tree = ast.parse(path.read_text())
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef)) and node.body
                  and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return [node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings]


def _modules(folder: str, package: str) -> dict[str, Path]:
    """Every module under ``folder``, subpackages included, by its dotted name (``hnn.models.mlp``;
    a package's ``__init__.py`` under the package's name)."""
    out = {}
    for path in sorted((REPO / folder).rglob("*.py")):
        parts = path.relative_to(REPO / folder).with_suffix("").parts
        out[".".join((package, *parts[:-1]) if parts[-1] == "__init__" else (package, *parts))] = path
    return out


def test_the_package_names_no_task():
    names = set(hnn.available_tasks())
    modules = _modules("hnn", "hnn")
    assert {"hnn.models.mlp", "hnn.integrators.solvers", "hnn.models"} <= set(modules)     # the subpackages too
    for name, path in modules.items():
        named = [s for s in _code_strings(path) if s in names or s.removeprefix("experiment-") in names]
        assert not named, f"{name} names the tasks {named}: a task describes itself in its task.py"


class _AnyData:
    """A task's data module that builds nothing: every function returns a MagicMock."""

    def __getattr__(self, name):
        from unittest import mock
        return lambda *args, **kwargs: mock.MagicMock()


def _fields_read(config, method: str) -> set[str]:
    """The dataclass fields of ``config`` that ``config.<method>()`` reads, with every data module stubbed."""
    import copy
    import dataclasses
    names, read = {f.name for f in dataclasses.fields(config)}, set()

    def record(self, name):
        if name in names:
            read.add(name)
        return object.__getattribute__(self, name)
    probe = copy.copy(config)
    probe.__class__ = type("Probe", (type(config),), {"__getattribute__": record})
    getattr(probe, method)()
    return read


@pytest.mark.parametrize("task", hnn.available_tasks())
def test_every_field_a_tasks_dataset_reads_decides_its_dataset_key(task, monkeypatch):
    """Runs of a sweep that agree on ``dataset_key()`` share one dataset: a field that ``dataset()`` reads
    but the key does not (``DATASET_FIELDS`` forgotten) would give runs that differ in it one dataset, silently.
    Display-only fields (worker counts) change how fast, not what is built."""
    config = hnn.tasks.task_config(task)
    monkeypatch.setattr(hnn.tasks, "load_task", lambda name, module="data": _AnyData())
    monkeypatch.setattr(hnn, "load_task", hnn.tasks.load_task, raising=False)
    read = _fields_read(config, "dataset")
    assert read, f"{task}: dataset() read no field of its config"
    missing = read - _fields_read(config, "dataset_key") - set(config.display_only())
    assert not missing, f"{task}: dataset() reads {sorted(missing)}, which its DATASET_FIELDS leave out"
