"""analysis/peers.py on a tiny config: every stage runs, the table holds the peers' numbers beside ours."""
import json
import re
import shutil
from pathlib import Path

import pytest

import hnn
from hnn_analysis.chains import peer_measure, peer_plan, peer_record, peer_table, peers

TINY = {"bobs": (1,), "fields": {"n_train": 4, "n_test": 2, "hidden_dim": 8, "total_steps": 2},
        "test_starts": 3, "lnn_starts": 0, "lnn_fields": {}, "max_iterations": 3000}


def test_tiny_peers_table(tmp_path, monkeypatch, capsys):
    # from the LNN's own init (the table's CHNN rows start from lnn_convex), a fresh black-box L on one bob meets
    # d2L/dqdot2 = 0 along its first snippets: on an AVX2 box the run fails in training; on an AVX-512 one its 2
    # steps pass, its rollout blows up and its timing burst (3 steps and more) fails. Each is said in its cell
    # and the command does not fail for it
    monkeypatch.setattr(peer_plan, "CHNN_KIND_FIELDS", {})
    results = peers.main(["--out", str(tmp_path)], settings=TINY)
    row = results["rows"]["chain1"]
    lnn = row["lagrangian"]
    if "diverged" in lnn:
        assert re.fullmatch(r"SingularLagrangianError at (the test batch after )?training step [0-2] of 2: LagrangianNN: "
                            r"d2L/dqdot2 is singular at \d+ states", lnn["diverged"]), lnn
    else:
        assert lnn["blew_up"].startswith("dopri5 did not finish in 3000 iterations"), lnn
        assert "lagrangian" in row["seconds"] or "chain1/lagrangian/seed0 not timed" in capsys.readouterr().out
    for kind in set(peer_plan.kinds()) - {"lagrangian"}:
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
    assert ("| failed in training: SingularLagrangianError at " if "diverged" in lnn else "| blew up: dopri5 did not") in text
    # a rerun trains nothing: every run is found by its config
    again = peers.main(["--out", str(tmp_path)], settings=TINY)
    assert again["rows"]["chain1"]["floor"] == row["floor"]


def test_the_lnn_chnn_row_trains_from_its_convex_init(tmp_path):
    """The table's CHNN rows start the LNN from lnn_convex (issue 48): the same tiny table's LNN cell is
    a number, where from the LNN's own init it failed in training (test_tiny_peers_table)."""
    assert peer_plan.CHNN_KIND_FIELDS["lagrangian"]["init"] == "lnn_convex"
    entry = peers.main(["--out", str(tmp_path)], settings=TINY)["rows"]["chain1"]["lagrangian"]
    assert "diverged" not in entry and entry["n"] == 3 and 0 < entry["median"] <= 1, entry


def test_train_only_trains_and_records_and_a_later_run_builds_the_table_from_the_record(tmp_path, capsys):
    tiny = {**TINY, "kinds": ("baseline", "hnn")}
    trained = peers.main(["--out", str(tmp_path), "--train-only"], settings=tiny)
    assert set(trained["runs"]) == {"chain1/baseline/seed0", "chain1/hnn/seed0"}
    out = capsys.readouterr().out          # each run recorded as it finished, not all at the end
    assert out.count("peers: seed 0: 1 run recorded") == 2 and "2 of 2 runs recorded" in out
    assert not (tmp_path / "peers.json").exists()
    assert set(trained["record"]["runs"]) == {"chain1/baseline/seed0", "chain1/hnn/seed0"}
    results = peers.main(["--out", str(tmp_path)], settings=tiny)
    assert "peers: 2 runs recorded in" in capsys.readouterr().out
    assert {"baseline", "hnn"} <= set(results["rows"]["chain1"]) and (tmp_path / "peers.json").exists()
    with pytest.raises(SystemExit):
        peers.main(["--train-only", "--update-docs"])
    assert "drop one of them" in capsys.readouterr().err


def test_the_record_outlives_the_run_folders_and_a_stopped_sittings_runs_are_recorded(tmp_path, capsys):
    """A table trained over sittings on machines that do not keep their files: each run's numbers are in the
    record, so the table comes back the same with every run folder gone and nothing trained or measured."""
    tiny = {**TINY, "kinds": ("baseline", "hnn")}
    first = peers.main(["--out", str(tmp_path)], settings=tiny)
    for run in (tmp_path / "runs").iterdir():
        shutil.rmtree(run) if run.is_dir() else run.unlink()
    capsys.readouterr()
    again = peers.main(["--out", str(tmp_path)], settings=tiny)
    out = capsys.readouterr().out
    assert "0 to train" in out and "measured" not in out
    for kind in ("baseline", "hnn"):
        assert again["rows"]["chain1"][kind] == first["rows"]["chain1"][kind]
        assert again["curves"]["chain1"][kind]["test_loss"] == pytest.approx(
            first["curves"]["chain1"][kind]["test_loss"], rel=1e-3)      # kept to 4 significant digits
    assert again["rows"]["chain1"]["floor"] == first["rows"]["chain1"]["floor"]
    # a sitting stopped before its record: --record-only measures its saved runs into a record, trains nothing
    other = tmp_path / "other.json"
    peers.main(["--out", str(tmp_path / "b"), "--train-only", "--record", str(tmp_path / "b.json")], settings=tiny)
    recorded = peers.main(["--out", str(tmp_path / "b"), "--record-only", "--record", str(other)], settings=tiny)
    assert "0 to train" in capsys.readouterr().out
    def numbers(runs: dict) -> dict:        # all but the seconds the measuring took
        return {key: {k: v for k, v in entry.items() if k != "measuring"} for key, entry in runs.items()}
    assert numbers(recorded["record"]["runs"]) == numbers(json.loads((tmp_path / "b.json").read_text())["runs"])
    assert all(entry["measuring"] > 0 for entry in recorded["record"]["runs"].values())
    # a changed config is another run: trained and recorded beside the old one's entry
    changed = {**tiny, "fields": {**tiny["fields"], "total_steps": 3}}
    peers.main(["--out", str(tmp_path), "--train-only"], settings=changed)
    assert "0 runs reused, 2 to train" in capsys.readouterr().out


def test_a_record_that_cannot_be_read_or_was_measured_otherwise_is_refused_with_the_fix(tmp_path, capsys):
    tiny = {**TINY, "kinds": ("baseline",)}
    (tmp_path / "peers-runs.json").write_text('{"measuring": ')
    with pytest.raises(SystemExit):
        peers.main(["--out", str(tmp_path)], settings=tiny)
    assert "cannot be read" in capsys.readouterr().err
    (tmp_path / "peers-runs.json").unlink()
    peers.main(["--out", str(tmp_path), "--train-only"], settings=tiny)
    with pytest.raises(SystemExit):
        peers.main(["--out", str(tmp_path)], settings={**tiny, "test_starts": 4})
    err = capsys.readouterr().err
    assert "'test_starts': 3" in err and "'test_starts': 4" in err and "--record with another path" in err
    with pytest.raises(SystemExit):
        peers.main(["--record-only", "--update-docs"])
    assert "--record-only only records" in capsys.readouterr().err


def test_only_trains_the_runs_it_names_and_refuses_a_pattern_that_names_none(tmp_path, capsys):
    """A sitting trains part of the table (``--only``) into the same record; a pattern of no run is refused."""
    tiny = {**TINY, "kinds": ("baseline", "hnn")}
    trained = peers.main(["--out", str(tmp_path), "--train-only", "--only", "chain1/hnn/*"], settings=tiny)
    assert set(trained["runs"]) == {"chain1/hnn/seed0"} and set(trained["record"]["runs"]) == {"chain1/hnn/seed0"}
    for argv, words in ((["--train-only", "--only", "chain9/*"], "'chain9/*' matches no run of this plan"),
                        (["--only", "chain1/*"], "add --train-only")):
        with pytest.raises(SystemExit):
            peers.main(["--out", str(tmp_path), *argv], settings=tiny)
        assert words in capsys.readouterr().err
    rest = peers.main(["--out", str(tmp_path), "--train-only"], settings=tiny)
    assert set(rest["runs"]) == {"chain1/baseline/seed0"}, "the recorded run is not trained again"


def test_a_runs_expected_time_is_its_kinds_recorded_time_per_step_on_its_row_else_its_protocol(tmp_path):
    settings = {**TINY, "bobs": (1, 2, 3), "kinds": ("baseline", "hnn")}
    jobs = {job.key: job for job in peer_plan.plan_seeds(settings, tmp_path, range(2))}
    walls = {"chain1/hnn/seed0": 30.0, "chain1/hnn/seed1": 50.0, "chain2/hnn/seed0": 10.0}
    record = {"runs": {key: {"identity": jobs[key].config.key(), "wall": wall} for key, wall in walls.items()}}
    wanted = [jobs[key] for key in ("chain2/hnn/seed1", "chain3/hnn/seed0", "chain3/baseline/seed0")]
    # chain2's own row; chain3 has none: the median of the kind's three; the baseline is recorded nowhere
    assert peer_record.expected_seconds(record, wanted, list(jobs.values())) == {
        "chain2/hnn/seed1": 10.0, "chain3/hnn/seed0": 30.0}


def test_update_docs_refuses_a_smoke_run(capsys):
    with pytest.raises(SystemExit):
        peers.main(["--quick", "--update-docs"])
    assert "drop --quick" in capsys.readouterr().err


def test_the_card_names_the_cheapest_kind_within_2x_of_the_best():
    rows = {"chain2": {"a": {"mean": 1e-3}, "b": {"mean": 1.9e-3}, "c": {"mean": 2.1e-3}, "d": {"blew_up": "t = 1"},
                       "seconds": {"a": {"seconds": 900}, "b": {"seconds": 100}, "c": {"seconds": 10},
                                   "d": {"seconds": 1}}}}
    lines = peer_table.card({"meta": {"kinds": ["a", "b", "c", "d"]}, "rows": rows})
    # b is within 2x of a and cheaper; c is cheaper still but 2.1x off; d blew up
    assert lines[-1] == "| 2 | a 1.00e-03 | b 1.90e-03, 100 s | a, b | one seed: not tested | d (every seed) |"


def test_the_table_trains_the_kinds_whose_structure_the_chain_has(tmp_path):
    kinds = peer_plan.kinds()
    # the LNN, the peers' own method, though the scene studies leave it out; with its own activation
    assert "lagrangian" in kinds and not hnn.MODEL_KINDS["lagrangian"].studied
    jobs = peer_plan.plan({**TINY, "kinds": kinds, "lnn_starts": 1}, tmp_path)
    lnn = [job for job in jobs if "/lagrangian/" in job.key]
    assert len(lnn) == 2 and all(job.config.nonlinearity == "softplus" for job in lnn)
    assert all(job.config.nonlinearity == "tanh" for job in jobs if "/hnn/" in job.key)
    assert {"hnn", "mechanical", "constrained", "constrained_lagrangian"} <= set(kinds)
    # the chain has no friction and its kinetic energy depends on the angles
    assert not {kind for kind in kinds if hnn.MODEL_KINDS[kind].dissipative or hnn.MODEL_KINDS[kind].separable}
    assert "dissipative" in hnn.MODEL_KINDS and "separable" in hnn.MODEL_KINDS


def test_seeds_make_each_cell_a_mean_with_its_range_and_the_card_says_what_they_cannot_separate(tmp_path):
    results = peers.main(["--out", str(tmp_path), "--seeds", "2"], settings={**TINY, "kinds": ("hnn", "mechanical")})
    assert results["meta"]["seeds"] == [0, 1] and set(results["by_seed"]) == {0, 1}
    for kind in ("hnn", "mechanical"):
        one = [results["by_seed"][s]["chain1"][kind] for s in (0, 1)]
        cell = results["rows"]["chain1"][kind]
        if all("mean" in e for e in one):
            assert cell["seeds"] == [e["mean"] for e in one] and cell["mean"] == pytest.approx(sum(cell["seeds"]) / 2)
            assert cell["low"] == min(cell["seeds"]) and cell["high"] == max(cell["seeds"])
    assert "2 seeds (0..1) a kind" in (tmp_path / "peers.md").read_text()
    for kind, cost in results["rows"]["chain1"]["seconds"].items():    # every seed's run timed, and its wall kept
        timed = [results["by_seed"][s]["chain1"]["seconds"][kind] for s in (0, 1)]
        assert cost["seconds"] == pytest.approx(sum(t["seconds"] for t in timed) / 2)
        assert cost["walls"] == [t["wall"] for t in timed] and cost["low"] <= cost["seconds"] <= cost["high"]
    # a rerun that reuses every run counts every seed's wall time, not the first seed's
    results["meta"]["seconds"]["training"] = 0
    walls = sum(cost["walls"][s] for cost in results["rows"]["chain1"]["seconds"].values() for s in (0, 1))
    assert f"their recorded training wall times sum to {walls:.0f} s" in peer_table.markdown(results)


def test_seeds_measured_in_worker_processes_give_the_numbers_measured_here(tmp_path, monkeypatch):
    # from the LNN's own init its run fails in training or its rollout blows up (test_tiny_peers_table: which,
    # the box's kernels decide): a failure's cell, which the parent keeps
    monkeypatch.setattr(peer_plan, "CHNN_KIND_FIELDS", {})
    tiny = {**TINY, "kinds": ("hnn", "lagrangian")}
    here = peers.main(["--out", str(tmp_path), "--seeds", "2"], settings=tiny)
    # the same runs measured again into a second record, each seed in a worker
    pooled = peers.main(["--out", str(tmp_path), "--seeds", "2", "--jobs", "2", "--record", str(tmp_path / "pooled.json")],
                        settings=tiny)
    for seed in (0, 1):
        mine, theirs = here["by_seed"][seed]["chain1"], pooled["by_seed"][seed]["chain1"]
        assert set(mine) == set(theirs) and set(theirs["seconds"]) == set(mine["seconds"])
        for kind in ("hnn", "lagrangian"):
            if "mean" in mine[kind]:           # float64 rollouts of the same models: the same to rounding
                assert theirs[kind]["mean"] == pytest.approx(mine[kind]["mean"], rel=1e-9)
            else:
                assert theirs[kind] == mine[kind]
        assert {"diverged", "blew_up"} & set(theirs["lagrangian"]) and "mean" in theirs["hnn"]


def test_the_card_says_which_cheaper_kinds_the_timings_cannot_separate():
    def cost(*seconds):          # each seed's run timed alone on one thread, merged as the table merges them
        return peer_measure.cost_over_seeds([{"k": {"seconds": s, "steps_per_s": 8000 / s, "steps": 8000,
                                                    "wall": 2 * s}} for s in seconds])["k"]
    assert cost(300, 100, 200) == {"seconds": 200, "low": 100, "high": 300, "steps_per_s": 40, "steps": 8000,
                                   "walls": [600, 200, 400]}
    rows = {"chain2": {"a": {"mean": 1e-3}, "b": {"mean": 1.5e-3}, "c": {"mean": 1.8e-3}, "d": {"mean": 1.2e-3},
                       "seconds": {"a": cost(900, 950), "b": cost(300, 340), "c": cost(320, 380), "d": cost(400, 420)}}}
    line = peer_table.card({"meta": {"kinds": ["a", "b", "c", "d"]}, "rows": rows})[-1]
    # b is the cheapest within 2x; c's timings (320..380 s) overlap b's (300..340 s), d's (400..420 s) do not
    assert "| b 1.50e-03, 320 s (timings cannot tell it from c) |" in line
    rows["chain2"]["seconds"]["c"] = cost(350, 380)
    assert "| b 1.50e-03, 320 s |" in peer_table.card({"meta": {"kinds": ["a", "b", "c", "d"]}, "rows": rows})[-1]


def test_the_card_names_the_kinds_the_seeds_cannot_separate_from_the_best():
    def entry(*seeds):
        return {"mean": sum(seeds) / len(seeds), "seeds": list(seeds), "low": min(seeds), "high": max(seeds)}
    rows = {"chain2": {"a": entry(1.0e-3, 1.4e-3), "b": entry(1.3e-3, 1.9e-3), "c": entry(1.6e-3, 2.0e-3),
                       "seconds": {"a": {"seconds": 900}, "b": {"seconds": 100}, "c": {"seconds": 10}}}}
    line = peer_table.card({"meta": {"kinds": ["a", "b", "c"]}, "rows": rows})[-1]
    # b's range overlaps a's (1.3e-3 <= 1.4e-3): the seeds cannot tell them apart; c's does not
    assert line.startswith("| 2 | a 1.20e-03 |") and line.endswith("| a, b, c | b | none |")


def test_a_kind_that_failed_on_some_seed_is_left_out_of_the_card_and_named():
    def entry(*seeds, failed=None):
        return {"mean": sum(seeds) / len(seeds), "seeds": list(seeds), "low": min(seeds), "high": max(seeds),
                "failed": failed or {}}
    # "a" is best on the seeds that trained and the cheapest, but two of its five seeds failed in training
    rows = {"chain3": {"a": entry(0.9e-3, 1.0e-3, 1.1e-3, failed={0: "singular", 1: "singular"}),
                       "b": entry(1.2e-3, 1.4e-3), "c": entry(1.5e-3, 2.0e-3),
                       "seconds": {"a": {"seconds": 10}, "b": {"seconds": 300}, "c": {"seconds": 100}}}}
    line = peer_table.card({"meta": {"kinds": ["a", "b", "c"]}, "rows": rows})[-1]
    assert line.startswith("| 3 | b 1.30e-03 | c 1.75e-03, 100 s |") and line.endswith("| a (2 of 5) |")
    # with no kind left that trained on every seed, the row chooses nothing from failures, and says so
    rows["chain3"] = {"a": rows["chain3"]["a"], "seconds": {"a": {"seconds": 10}}}
    assert peer_table.card({"meta": {"kinds": ["a"]}, "rows": rows})[-1] == \
        "| 3 | every kind failed on some seed | | | | a (2 of 5) |"


def test_a_cell_says_how_many_seeds_failed_and_how_when_all_did():
    def measured(mean):
        return {"mean": mean, "median": mean / 2, "n": 100}
    singular = {"diverged": "SingularLagrangianError at training step 12 of 8000: LagrangianNN: d2L/dqdot2 is singular"}
    by_seed = {0: {"chain3": {"a": measured(0.3), "b": singular, "c": measured(1e-3)}},
               1: {"chain3": {"a": singular, "b": {"blew_up": "dopri5 (rtol=1e-07): 2 trajectories diverged"},
                              "c": measured(2e-3)}},
               2: {"chain3": {"a": singular, "b": singular, "c": singular}}}
    row = peer_measure.over_seeds(by_seed)["chain3"]
    # one seed measured and two failed: its number, never mistaken for a clean run
    assert row["a"]["seeds"] == [0.3] and set(row["a"]["failed"]) == {1, 2}
    assert peer_table._cell(row["a"]) == "3.00e-01 (1 seed; 2 more failed)"
    assert peer_table._cell(row["c"]) == "1.50e-03 (1.0e-03..2.0e-03, 2 seeds; 1 more failed)"
    # every seed failed: each seed's way, in seed order
    assert peer_table._cell(row["b"]) == (
        "failed on all 3 seeds: seed 0 failed in training: SingularLagrangianError at training step 12 of 8000; "
        "seed 1 blew up: dopri5 (rtol=1e-07); seed 2 failed in training: SingularLagrangianError at training step "
        "12 of 8000")
    assert {"diverged"} <= set(row["b"]) and "mean" not in row["b"]


def test_quick_trains_the_lnn_the_protocols_steps_and_says_what_it_cut(tmp_path):
    kinds = peer_plan.kinds()
    quick = {job.key: job.config for job in peer_plan.plan({**peer_plan.QUICK, "kinds": kinds}, tmp_path)}
    full = {job.key: job.config for job in peer_plan.plan({**peer_plan.FULL, "kinds": kinds}, tmp_path)}
    # the full table trains the LNN its own 60000 steps on its L1 loss; quick trains it the protocol's 100
    assert full["lnn/lagrangian/seed0"].total_steps == peer_plan.LNN_KIND_FIELDS["lagrangian"]["total_steps"] == 60000
    assert quick["lnn/lagrangian/seed0"].total_steps == peer_plan.QUICK["lnn_fields"]["total_steps"] == 100
    assert quick["lnn/lagrangian/seed0"].derivative_loss == full["lnn/lagrangian/seed0"].derivative_loss == "l1"
    assert max(config.total_steps for config in quick.values()) == 100
    cuts = peer_plan.quick_cuts()
    assert "LNN protocol: its lagrangian kind 100 steps of its own 60000" in cuts
    assert "N = 1, 2 of 1, 2, 3, 5 bobs" in cuts and "CHNN protocol: 100 training steps of 8000" in cuts
    assert "1 seed of 5 (--seeds sets it)" in cuts
    assert "LNN protocol: 2 energy starts of 40" in cuts and "CHNN protocol: 10 test starts of 100" in cuts
    assert "LNN protocol: the energy error at T = 10 s of their 100 s" in cuts
    assert "rollouts stop at 1000 dopri5 iterations (full: 100000)" in cuts


def test_our_implementations_stand_beside_the_published_means_on_their_seeds():
    def entry(*seeds):
        return {"mean": sum(seeds) / len(seeds), "seeds": list(seeds), "low": min(seeds), "high": max(seeds)}
    published = {2: {"CHNN": (5.0e-4, 1e-4), "CLNN": (2.0e-4, 1e-4), "HNN": (1.0e-2, 1e-3)}}
    rows = {"chain2": {"constrained": entry(1.0e-4, 1.5e-4, 2.0e-4),             # every seed below: 3.3x
                       "constrained_lagrangian": entry(1.5e-4, 2.5e-4, 3.5e-4),  # straddles, within 2x
                       "mechanical": {"mean": 3.0e-2, "median": 2.0e-2}},         # one seed, 3x above
              "lnn": {}}
    lines = peer_table.against_published({"rows": rows}, published)
    assert "| 2 | CHNN (ours: constrained) | 5.00e-04 | 1.50e-04 | 0.30 | no: 3.3x below (better) | " \
           "below on every seed |" in lines
    assert "| 2 | CLNN (ours: constrained_lagrangian) | 2.00e-04 | 2.50e-04 | 1.25 | yes | " \
           "the seeds straddle it |" in lines
    assert "| 2 | HNN (ours: mechanical) | 1.00e-02 | 3.00e-02 | 3.00 | no: 3.0x above (worse) | " \
           "one seed: not tested |" in lines
    assert peer_table.beside(entry(6e-4, 7e-4), 5e-4)[1] == "above on every seed"
    # a kind some of whose seeds failed in training: its mean is over the rest, and the row says how many
    rows["chain2"]["constrained"]["failed"] = {3: "singular"}
    assert any(line.endswith("| below on every seed; 1 of 4 failed (in training, or the rollout blew up) |")
               for line in peer_table.against_published({"rows": rows}, published))
    # a row no kind of ours measured, or a table without the chain, adds no section
    assert peer_table.against_published({"rows": {"lnn": {}}}, published) == []


def test_the_committed_record_holds_runs_of_the_full_tables_plan():
    """docs/peers-runs.json keeps the full table's finished runs between sittings: a change to a kind's or a
    protocol's config makes its recorded runs another config's, retrained by the next sitting, and this
    test names them, so such a change is made knowingly."""
    settings = {"kinds": peer_plan.kinds(), **peer_plan.FULL}
    record = peer_record.load(hnn.tasks.repo_root() / peer_record.RECORD, settings)    # raises if measured otherwise
    jobs = {job.key: job for job in peer_plan.plan_seeds(settings, hnn.tasks.repo_root() / "results" / "peers",
                                                         range(peer_plan.FULL_SEEDS))}
    stale = sorted(key for key, entry in record["runs"].items()
                   if key not in jobs or entry["identity"] != jobs[key].config.key())
    assert not stale, f"recorded runs the full table no longer trains (their configs changed): {stale}"
    for key, entry in record["runs"].items():
        assert set(entry["entry"]) in ({"mean", "median", "n"}, {"blew_up"}, {"diverged"}), (key, entry)


def test_the_lnn_runs_that_stopped_are_the_tables_with_the_pseudo_inverse_config():
    """analysis/stress.py --lnn-pinv trains again each LNN run of the peers' table that stopped with a singular
    d2L/dqdot2 under the plain solve: 12 on the chains (chain2 seeds 0, 2, 3; chain3 seeds 1-4; chain5 every seed),
    at steps 144 to 1846 of 8000 (those of chain5 as docs/peers.md's table quotes them), and seed 4 of the LNN
    protocol, each the table's job with its config (now the pseudo-inverse solve, as the table trains the LNN)."""
    from hnn_analysis.chains import lnn_pinv
    stopped = lnn_pinv.PLAIN_STOPS
    assert sorted(stopped) == sorted([f"chain2/lagrangian/seed{s}" for s in (0, 2, 3)]
                                     + [f"chain3/lagrangian/seed{s}" for s in (1, 2, 3, 4)]
                                     + [f"chain5/lagrangian/seed{s}" for s in range(5)] + ["lnn/lagrangian/seed4"])
    assert (min(stopped.values()), max(v for k, v in stopped.items() if k.startswith("chain"))) == (144, 1846)
    quoted = re.findall(r"seed (\d) failed in training: SingularLagrangianError at training step (\d+) of 8000",
                        (hnn.tasks.repo_root() / "docs" / "peers.md").read_text())
    assert {f"chain5/lagrangian/seed{s}": int(step) for s, step in quoted} == {
        key: step for key, step in stopped.items() if key.startswith("chain5")}
    job = lnn_pinv._job("chain5/lagrangian/seed1", Path("runs"))
    assert job.config.lnn_solve == "pinv" and (job.config.bobs, job.config.seed, job.config.total_steps) == (5, 1, 8000)
    assert peer_plan.KIND_FIELDS["lagrangian"]["lnn_solve"] == "pinv"
