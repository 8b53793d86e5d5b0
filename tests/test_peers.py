"""analysis/peers.py on a tiny config: every stage runs, the table holds the peers' numbers beside ours."""
import json
import re

import pytest

import hnn
from hnn_analysis.chains import peers

TINY = {"bobs": (1,), "fields": {"n_train": 4, "n_test": 2, "hidden_dim": 8, "total_steps": 2},
        "test_starts": 3, "lnn_starts": 0, "lnn_fields": {}, "max_iterations": 3000}


def test_tiny_peers_table(tmp_path, monkeypatch):
    # from the LNN's own init (the table's CHNN rows start from lnn_convex), a fresh black-box L on one bob has
    # d2L/dqdot2 = 0 somewhere along its first snippets: the run fails in training, deterministically, and the
    # table says so in its cell (the command does not fail for it)
    monkeypatch.setattr(peers, "CHNN_KIND_FIELDS", {})
    results = peers.main(["--out", str(tmp_path)], settings=TINY)
    row = results["rows"]["chain1"]
    assert re.fullmatch(r"SingularLagrangianError at (the test batch after )?training step [0-2] of 2: LagrangianNN: "
                        r"d2L/dqdot2 is singular at \d+ states", row["lagrangian"]["diverged"]), row["lagrangian"]
    for kind in set(peers.kinds()) - {"lagrangian"}:
        entry = row[kind]
        assert "blew_up" in entry or (entry["n"] == 3 and 0 < entry["median"] <= 1), (kind, entry)
        cost = row["seconds"][kind]            # steps at a rate timed alone on one thread, and the wall time
        assert cost["steps"] == 3 and cost["seconds"] > 0 and cost["wall"] > 0
        curve = results["curves"]["chain1"][kind]   # held-out loss at steps 0 and 2, in CHNN epochs of 4 steps
        assert curve["epochs"] == [0.0, 0.5] and len(curve["test_loss"]) == 2
    assert (tmp_path / "figures" / "peers-curves.png").stat().st_size > 0
    # the chaos floor of one bob from 3 starts: the published one is 4.9e-5 (100 starts)
    assert 1e-5 < row["floor"]["mean"] < 2e-4
    text = (tmp_path / "peers.md").read_text()
    assert text.startswith("**QUICK smoke run**") and "| 1 | 1.80e-04 (1.12e-04) | 7.46e-05 (6.09e-05) | 7.40e-05" in text
    assert json.loads((tmp_path / "peers.json").read_text())["meta"]["quick"] is True
    assert "From `python analysis/peers.py --out DIR` at commit" in text
    assert "| failed in training: SingularLagrangianError at " in text
    # a rerun trains nothing: every run is found by its config
    again = peers.main(["--out", str(tmp_path)], settings=TINY)
    assert again["rows"]["chain1"]["floor"] == row["floor"]


def test_the_lnn_chnn_row_trains_from_its_convex_init(tmp_path):
    """The table's CHNN rows start the LNN from lnn_convex (issue 48): the same tiny table's LNN cell is
    a number, where from the LNN's own init it failed in training (test_tiny_peers_table)."""
    assert peers.CHNN_KIND_FIELDS["lagrangian"]["init"] == "lnn_convex"
    entry = peers.main(["--out", str(tmp_path)], settings=TINY)["rows"]["chain1"]["lagrangian"]
    assert "diverged" not in entry and entry["n"] == 3 and 0 < entry["median"] <= 1, entry


def test_update_docs_refuses_a_smoke_run(capsys):
    with pytest.raises(SystemExit):
        peers.main(["--quick", "--update-docs"])
    assert "drop --quick" in capsys.readouterr().err


def test_the_card_names_the_cheapest_kind_within_2x_of_the_best():
    rows = {"chain2": {"a": {"mean": 1e-3}, "b": {"mean": 1.9e-3}, "c": {"mean": 2.1e-3}, "d": {"blew_up": "t = 1"},
                       "seconds": {"a": {"seconds": 900}, "b": {"seconds": 100}, "c": {"seconds": 10},
                                   "d": {"seconds": 1}}}}
    lines = peers.card({"meta": {"kinds": ["a", "b", "c", "d"]}, "rows": rows})
    # b is within 2x of a and cheaper; c is cheaper still but 2.1x off; d blew up
    assert lines[-1] == "| 2 | a 1.00e-03 | b 1.90e-03, 100 s | a, b |"


def test_the_table_trains_the_kinds_whose_structure_the_chain_has(tmp_path):
    kinds = peers.kinds()
    # the LNN, the peers' own method, though the scene studies leave it out; with its own activation
    assert "lagrangian" in kinds and not hnn.MODEL_KINDS["lagrangian"].studied
    jobs = peers.plan({**TINY, "kinds": kinds, "lnn_starts": 1}, tmp_path)
    lnn = [job for job in jobs if "/lagrangian/" in job.key]
    assert len(lnn) == 2 and all(job.config.nonlinearity == "softplus" for job in lnn)
    assert all(job.config.nonlinearity == "tanh" for job in jobs if "/hnn/" in job.key)
    assert {"hnn", "mechanical", "constrained", "constrained_lagrangian"} <= set(kinds)
    # the chain has no friction and its kinetic energy depends on the angles
    assert not {kind for kind in kinds if hnn.MODEL_KINDS[kind].dissipative or hnn.MODEL_KINDS[kind].separable}
    assert "dissipative" in hnn.MODEL_KINDS and "separable" in hnn.MODEL_KINDS
