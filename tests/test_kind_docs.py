"""Every model kind is introduced: each row of ``hnn.MODEL_KINDS`` carries its prose, the README and
docs/python.md show them as ``analysis/readme.py kinds`` writes them, ``--model``'s help lists them,
and the names the flags offer before torch loads are the modules' own."""
import dataclasses
import subprocess
import sys

import pytest
import torch

import hnn
from hnn import models
from hnn_analysis import pages


def test_every_registered_kind_is_described_and_on_both_pages():
    for kind, doc in hnn.kinds.described():
        assert isinstance(doc, hnn.kind_docs.KindDoc), kind
        assert all(getattr(doc, f.name).strip() for f in dataclasses.fields(doc)), kind
    assert pages.declared_out_of_date() == []
    root = hnn.tasks.repo_root()
    readme_page, python_page = (root / "README.md").read_text(), (root / "docs" / "python.md").read_text()
    for kind in hnn.MODEL_KINDS:
        assert f"- `{kind}`: " in readme_page and f"**`{kind}`**: " in python_page, kind


def test_a_kind_left_out_of_a_page_is_found(monkeypatch):
    monkeypatch.setitem(hnn.MODEL_KINDS, "extra", hnn.MODEL_KINDS["hnn"])
    assert len(pages.declared_out_of_date()) == 2          # both pages lack it
    monkeypatch.setitem(hnn.MODEL_KINDS, "extra", dataclasses.replace(hnn.MODEL_KINDS["hnn"], doc=None))
    [line] = pages.declared_out_of_date()
    assert "extra" in line and "hnn/kinds.py" in line and "KindDoc" in line


def test_model_help_lists_every_kind_a_task_takes():
    for task in hnn.available_tasks():
        Config = hnn.load_task(task, "train").Config
        text = "".join(hnn.cli.make_parser(Config).format_help().split())    # argparse wraps lines at hyphens
        for kind in hnn.cli.model_choices(Config):
            line = "".join(hnn.MODEL_KINDS[Config.KIND_PREFIX + kind].doc.line.split())
            assert f"{kind}({line})" in text, (task, kind)
    spring = hnn.load_task("spring", "train").Config
    assert set(hnn.cli.model_choices(spring)) == {kind for kind, row in hnn.MODEL_KINDS.items() if row.family is None}


def test_every_module_keys_its_options_from_the_one_list():
    """Each option's names are hnn.names' list; each implementing table holds every name, and each name
    reaches a working implementation (an activation of the right shape, an objective class, a loss)."""
    assert (models.NONLINEARITIES, models.INITS, models.FIELD_TYPES) == (
        hnn.names.NONLINEARITIES, hnn.names.INITS, hnn.names.FIELD_TYPES)
    x = torch.linspace(-2, 2, 9)
    for name in hnn.names.NONLINEARITIES:
        y = models.get_nonlinearity(name)(x)
        assert y.shape == x.shape and torch.isfinite(y).all() and not torch.equal(y, x), name
    torch.testing.assert_close(models.get_nonlinearity("swish")(x), x * torch.sigmoid(x))
    assert models.get_nonlinearity("tanh") is models.tanh_mlp.fast_tanh      # the closed form's own
    assert tuple(hnn.kinds.OBJECTIVES) == hnn.names.OBJECTIVES
    assert all(issubclass(hnn.OBJECTIVES[name], hnn.Objective) for name in hnn.names.OBJECTIVES)
    assert tuple(hnn.training.DERIVATIVE_LOSSES) == hnn.names.DERIVATIVE_LOSSES
    assert tuple(models.hamiltonian.FIELD_ROWS) == hnn.names.FIELD_TYPES
    assert models.hamiltonian.FIELD_ROWS["solenoidal"] == (1,)       # H = F2: Hamilton's equations
    for init in hnn.names.INITS:
        models.initialize(models.MLP(2, 4, 2), init)
    for name in hnn.names.OPTIMIZERS:       # each builds an optimizer that steps
        w = torch.nn.Linear(1, 1)
        hnn.trainers.loop.adam_optimizer(w, 1e-2, 0.0, name).step()
    with pytest.raises(ImportError, match=r"lacks \['adamw'\] and has extra \['sgd'\]"):
        hnn.names.checked({"adam": torch.optim.Adam, "sgd": torch.optim.SGD}, hnn.names.OPTIMIZERS, "optimizers")
    for schedule in hnn.names.SCHEDULES:
        assert hnn.trainers.loop.learning_rate(1.0, 0, 10, schedule) == 1.0
    assert all(isinstance(getattr(torch, name), torch.dtype) for name in hnn.names.DTYPES)


def test_the_kinds_table_loads_without_torch():
    """--help reads every kind's row and prose before torch loads: the class is imported on first build."""
    code = ("import sys; from hnn.kinds import MODEL_KINDS; import hnn.cli; "
            "print(len(MODEL_KINDS), all(r.doc for r in MODEL_KINDS.values()), 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == [str(len(hnn.MODEL_KINDS)), "True", "False"]


def test_a_row_naming_its_class_wrongly_says_so():
    with pytest.raises(ValueError, match="is not 'module:name'"):
        hnn.kinds.ModelKind("hnn.models.hamiltonian.HNN")
    with pytest.raises(ImportError, match="has no Nope"):
        hnn.kinds.ModelKind(".models.hamiltonian:Nope").reads("canonical")
    with pytest.raises(TypeError, match="must be an hnn.Model subclass"):
        hnn.kinds.ModelKind(".models.mlp:MLP").reads("canonical")        # a network, not a model
    row = hnn.kinds.ModelKind(".models.structured:SeparableHNN")      # the default builder and objective
    model = row.build(hnn.kinds.ModelSpec("x", input_dim=2, hidden_dim=4))
    assert isinstance(model, hnn.SeparableHNN) and isinstance(row.make_objective(), hnn.DerivativeObjective)


def test_a_kinds_family_and_grouping_are_declared_on_its_row():
    """--model's default choices are the kinds of no family; a hyphenated name needs its family; a grouping is
    one of hnn.names.GROUPINGS; the closed form groups exactly the kinds hnn.trainers.closed_form has gradients for."""
    assert {k for k, row in hnn.MODEL_KINDS.items() if row.family == "pixel"} == {"pixel-hnn", "pixel-baseline"}
    assert {k for k, row in hnn.MODEL_KINDS.items() if row.grouping == "closed_form"} == {
        "hnn", "baseline", "separable", "dissipative"}
    with pytest.raises(ValueError, match="grouping='batched'"):
        hnn.kinds.ModelKind(".models.hamiltonian:HNN", grouping="batched")
    with pytest.raises(ImportError, match="'toy-hnn'"):
        hnn.kinds._check_names({"toy-hnn": hnn.kinds.ModelKind(".models.hamiltonian:HNN")})
    with pytest.raises(ImportError, match="'toy'"):
        hnn.kinds._check_names({"toy": hnn.kinds.ModelKind(".models.hamiltonian:HNN", family="pixel")})
