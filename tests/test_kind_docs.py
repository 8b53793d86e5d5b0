"""Every model kind is introduced: ``hnn.kind_docs`` describes each kind of ``hnn.MODEL_KINDS``,
the README and docs/python.md show them as ``analysis/readme.py kinds`` writes them, ``--model``'s
help lists them, and the names the flags offer before torch loads are the modules' own."""
import dataclasses

import hnn
from hnn import models
from hnn_analysis import readme


def test_every_registered_kind_is_described_and_on_both_pages():
    assert set(hnn.kind_docs.KIND_DOCS) == set(hnn.MODEL_KINDS)
    for kind, doc in hnn.kind_docs.KIND_DOCS.items():
        assert all(getattr(doc, f.name).strip() for f in dataclasses.fields(doc)), kind
    assert readme.declared_out_of_date() == []
    root = hnn.tasks.repo_root()
    readme_page, python_page = (root / "README.md").read_text(), (root / "docs" / "python.md").read_text()
    for kind in hnn.MODEL_KINDS:
        assert f"- `{kind}`: " in readme_page and f"**`{kind}`**: " in python_page, kind


def test_a_kind_left_out_of_a_page_is_found(monkeypatch):
    monkeypatch.setitem(hnn.MODEL_KINDS, "extra", hnn.MODEL_KINDS["hnn"])
    [line] = readme.declared_out_of_date()
    assert "extra" in line and "hnn/kind_docs.py" in line


def test_model_help_lists_every_kind_a_task_takes():
    for task in hnn.available_tasks():
        Config = hnn.load_task(task, "train").Config
        text = "".join(hnn.cli.make_parser(Config).format_help().split())    # argparse wraps lines at hyphens
        for kind in hnn.cli.model_choices(Config):
            line = "".join(hnn.kind_docs.KIND_DOCS[Config.KIND_PREFIX + kind].line.split())
            assert f"{kind}({line})" in text, (task, kind)
    spring = hnn.load_task("spring", "train").Config
    assert set(hnn.cli.model_choices(spring)) == {kind for kind in hnn.MODEL_KINDS if "-" not in kind}


def test_the_names_known_before_torch_are_the_modules_own():
    assert hnn.names.NONLINEARITIES == models.NONLINEARITIES
    assert hnn.names.INITS == models.INITS
    assert hnn.names.FIELD_TYPES == models.FIELD_TYPES
    assert hnn.names.OBJECTIVES == tuple(hnn.kinds.OBJECTIVES)
    assert hnn.names.DERIVATIVE_LOSSES == tuple(hnn.training.DERIVATIVE_LOSSES)
