"""The bodies study (analysis/bodies.py): a pair model fitted on 8 bodies rolls out chains of other lengths. The
radial library recovers the lattice's spring exactly, so its paths at every N are the true forces' leapfrog
paths to round-off: the study's energy and rollout errors for it equal the true forces' to that precision."""
import pytest

from hnn_analysis.scenes import bodies_study as bodies


def test_the_exact_library_runs_zero_shot_as_the_true_forces_do():
    results = bodies.study(sizes=(8, 20), fits=("library",), seed=0, starts=2, dt=0.1, horizon=2.0,
                           adam_steps=0, hidden=8)
    assert [row["N"] for row in results["rows"]] == [8, 20]
    for row in results["rows"]:
        mine, true = row["library"], row["true"]
        # the leapfrog's own error (dt 0.1 over 2 time units) is far above round-off: the two paths agree to
        # the fit's coefficients, recovered to a few hundred eps (tests/test_lattice.py)
        assert mine["rollout"] == pytest.approx(true["rollout"], rel=1e-6)
        assert mine["energy_per_body"] == pytest.approx(true["energy_per_body"], rel=1e-6)
        assert true["rollout"] > 1e-6 and mine["seconds_per_step"] > 0
    assert "sum r^2" in results["fits"]["library"]["what"]
    results["meta"] = {"command": "python analysis/bodies.py --quick", "cores": 2, "cpu": "test"}
    text = bodies.table(results)
    assert "| 20 |" in text and "**library**" in text


def test_the_sizes_measured_in_worker_processes_give_the_rows_measured_here():
    """Each N is a cell (the fits rebuilt from their args and weights in the worker): two processes give the
    rows one process gives, bit for bit but the seconds, and the page says the sizes shared the machine."""
    kwargs = dict(sizes=(8, 12), fits=("library", "swim"), seed=0, starts=1, dt=0.1, horizon=0.5, adam_steps=0,
                  hidden=8)
    here, workers = bodies.study(**kwargs), bodies.study(**kwargs, jobs=2)

    def numbers(results):
        return [{part: {k: v for k, v in cell.items() if k not in ("seconds_per_step", "timed")}
                 for part, cell in row.items() if isinstance(cell, dict)} for row in results["rows"]]
    assert [row["N"] for row in workers["rows"]] == [8, 12]
    assert numbers(workers) == numbers(here)
    assert workers["settings"]["jobs"] == 2 and here["settings"]["jobs"] == 1
    workers["meta"] = here["meta"] = {"command": "python analysis/bodies.py", "cores": 2, "cpu": "test"}
    assert "measured 2 at a time" in bodies.table(workers) and "at a time" not in bodies.table(here)


def test_the_paper_protocols_plan_the_pair_rungs_and_judge_them_against_the_targets(tmp_path):
    import math

    import torch

    import hnn
    from hnn_analysis.scenes import bodies_paper

    jobs = bodies_paper.plan(bodies_paper.TASKS, [0, 1], tmp_path, quick=False)
    assert {job.key for job in jobs} == {f"{task}/{label}/seed{s}" for task in ("2body", "3body")
                                         for label in bodies_paper.RUNGS for s in (0, 1)}
    assert all(job.config.kind == "pairwise" for job in jobs)
    # the true H scores zero; a learned H off by a constant too (its constant is fixed at the anchor state)
    system = hnn.load_task("3body")
    x = torch.randn(50, 12, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 2

    class Shifted(torch.nn.Module):
        def hamiltonian(self, states):
            return system.hamiltonian(states) + 3.0
    assert bodies_paper.h_error(Shifted(), x, x[:1], system.hamiltonian) <= 50 * torch.finfo(torch.float64).eps

    def seeds(energy, seconds, error, equation=None):
        return {s: {"energy_mse": [energy, 0.0], "train_seconds": seconds, "h_error": error, "test_loss": 1e-3,
                    "equation": equation} for s in range(5)}
    entry = {"reference": {"energy_mse": [4.19e-2, 3.4e-2], "train_seconds": 50.0},
             "rungs": {"pairwise": seeds(1e-4, 40.0, 1e-2), "pairwise+library": seeds(1e-15, 1.0, 1e-8, "H = x"),
                       "pairwise+swim": seeds(1e-7, 70.0, 2e-3)}}
    said = bodies_paper.verdicts("3body", entry)
    assert "419x below the paper's HNN" in said[0] and "target 100x: met" in said[0] and said[0].endswith("(met).")
    assert "`H = x`" in said[1]
    assert "(error met, seconds not met)" in said[2]         # 70 s against their 58
    entry["rungs"]["pairwise"] = {**seeds(1e-4, 40.0, 1e-2), 4: {**seeds(math.inf, 40.0, 1e-2)[4]}}
    failed = bodies_paper.verdicts("3body", entry)[0]
    assert "rollout failed (1 of 5 seeds)" in failed and "target 100x: not met" in failed
    results = {"meta": {"command": "python analysis/bodies.py --paper", "date": "2026-01-01", "commit": "abcdef1",
                        "cores": 2, "cpu": "test", "torch": "2", "seeds": list(range(5))}, "tasks": {"3body": entry}}
    text = bodies_paper.table(results)
    assert "| the paper's HNN | 0.0419 (published) | 50 |" in text and "| pairwise+swim |" in text


def test_the_pair_rungs_are_planned_exactly_where_a_task_declares_bodies(tmp_path):
    from hnn_analysis.fits import task_fits
    from hnn_analysis.scenes import scene_common, scene_rungs, scene_stages

    pair = {"pairwise", "pairwise+swim", "pairwise+library"}
    for task in scene_common.scenes():
        assert (pair <= set(scene_common.task_rungs(task))) == (task in ("2body", "3body")), task
        assert not pair & set(scene_common.task_rungs(task)) or task in ("2body", "3body"), task
    # the full study's jobs at the default cell: every rung asked of every scene, the pixels' own kinds too
    rows = [row for row in scene_stages.plan_rows(scene_common.scenes(), False)
            if row["cell"] == scene_stages.DEFAULT_CELL]
    rungs = scene_stages.rungs_of(False)[0]
    keys = {job.key for job in scene_rungs.jobs(rows, [0], tmp_path, rungs, scene_common._fits)}
    assert {key.split("/")[0].split("@")[0] for key in keys if "/pairwise+" in key} == {"2body", "3body"}
    for task in task_fits.TASKS:
        assert (pair <= set(task_fits.rungs(task))) == (task in ("2body", "3body")), task
        assert not pair & set(task_fits.rungs(task)) or task in ("2body", "3body"), task


def test_gravity_runs_zero_shot_and_a_diverged_model_is_a_row_that_says_so():
    results = bodies.study(sizes=(8, 70), fits=("swim",), seed=0, starts=1, dt=0.01, horizon=0.05, adam_steps=0,
                           hidden=8, scene="gravity")       # 70 bodies: past nbody.DENSE_BODIES, the blocked sums
    assert [row["N"] for row in results["rows"]] == [8, 70] and results["settings"]["scene"] == "gravity"
    for row in results["rows"]:
        # the true forces' leapfrog over 5 steps of 0.01: its energy error is the step's, far below the energy per
        # body (about 2 at N = 8); its rollout error against DOP853 at rtol 1e-10 too
        assert 0 < row["true"]["energy_per_body"] < 1e-2 and row["true"]["rollout"] < 1e-3
        assert "diverged" in row["swim"] or row["swim"]["energy_per_body"] >= 0
    row = {"N": 64, "true": {"energy_per_body": 1e-3, "rollout": 1e-4, "seconds_per_step": 1e-3},
           "swim": {"diverged": "leapfrog (dt=0.01): 1 trajectories diverged", "seconds_per_step": 2e-3}}
    results["rows"].append(row)
    results["meta"] = {"command": "python analysis/bodies.py --scene gravity", "cores": 2, "cpu": "test"}
    text = bodies.table(results)
    assert "| 64 | diverged: leapfrog (dt=0.01): 1 trajectories diverged | 1.00e-03 | | 1.00e-04 | 2.000 |" in text
    assert "softened gravity" in text


def test_a_model_past_memory_is_a_row_that_says_how_much_it_needs(monkeypatch):
    from hnn.models import pair

    # the fit's design (3200 states of 28 pairs, 20 numbers each: 14 MB) at the full limit; then 64 kB, which 8
    # bodies' field call (28 pairs, 9 numbers each) and the true forces' rows of 600 bodies (6 numbers a pair: 29 kB)
    # fit, but not one of 600 bodies' rows against every body in the sampled fit's blocks (31 numbers a pair: 149 kB)
    fit = bodies._fit

    def fit_then_shrink(*args):
        out = fit(*args)
        monkeypatch.setattr(pair, "PAIR_BYTES", 2 ** 16)
        return out

    monkeypatch.setattr(bodies, "_fit", fit_then_shrink)
    results = bodies.study(sizes=(8, 600), fits=("swim",), seed=0, starts=1, dt=0.01, horizon=0.02, adam_steps=0,
                           hidden=8, scene="gravity")
    big = results["rows"][1]["swim"]
    assert "too many pairs" in big["diverged"] and "GiB" in big["diverged"] and big["seconds_per_step"] is None
    results["meta"] = {"command": "python analysis/bodies.py", "cores": 2, "cpu": "test"}
    assert "| n/a | " in bodies.table(results)


def test_the_lennard_jones_scene_runs_with_its_cutoff_and_the_library_follows_the_true_forces():
    import numpy as np
    import torch

    import hnn

    # the scene's declared task settings reach its config (the cut dataset) and its true functions alike
    assert bodies.SCENES["lj"]["settings"] == {"cutoff": 2.5}
    results = bodies.study(sizes=(8, 40), fits=("library",), seed=0, starts=1, dt=0.01, horizon=0.1, adam_steps=0,
                           hidden=8, scene="lj")
    assert [row["N"] for row in results["rows"]] == [8, 40]
    assert results["settings"]["task_settings"] == {"cutoff": 2.5}
    # the library recovers the shifted Lennard-Jones to round-off (tests/test_lj.py), so its paths are the true cut
    # forces' leapfrog paths to that precision, at 8 bodies and at 40 (pairs beyond r_c: a cell list). The task's data
    # are float32: the coefficients carry its eps (6e-8) times the two columns' condition (~1e3), 6e-5 relative at
    # most (4e-8 measured), and the errors below move by no more than that part of themselves
    assert "sum over r < 2.5 of [V(r) - V(2.5)], V = - 4 1/r^6 + 4 1/r^12" in results["fits"]["library"]["what"]
    for row in results["rows"]:
        mine, true = row["library"], row["true"]
        assert true["rollout"] > 1e-6 and true["energy_per_body"] > 1e-6
        assert mine["rollout"] == pytest.approx(true["rollout"], rel=1e-4)
        assert mine["energy_per_body"] == pytest.approx(true["energy_per_body"], rel=1e-4)
    results["meta"] = {"command": "python analysis/bodies.py --scene lj", "cores": 2, "cpu": "test"}
    text = bodies.table(results)
    assert "Lennard-Jones cluster of 8 bodies (seed 0, task settings: cutoff 2.5)" in text and "| 40 |" in text
    # a larger cluster keeps the training's density: the start law's nearest neighbours sit at one spacing at any N
    data = hnn.load_task("lj")
    rng = np.random.RandomState(0)
    nearest = []
    for count in (8, 1024):
        q, _ = data.layout(count).split(torch.tensor(data.random_config(rng, count))[None])
        gaps = torch.cdist(q[0], q[0]) + torch.eye(count, dtype=torch.float64) * 1e9
        nearest.append(float(gaps.min(dim=1).values.mean()))
    # the lattice's spacing 2^(1/6) less a jitter of 0.03 per coordinate: the means agree to a few jitters / sqrt(N)
    assert nearest[1] == pytest.approx(nearest[0], rel=0.05) and nearest[1] == pytest.approx(data.SPACING, rel=0.05)


def test_a_model_whose_paths_reach_the_lennard_jones_wall_is_a_row_that_says_so(monkeypatch):
    import torch

    # the library with its signs flipped: V = 4 (r^-6 - r^-12) pulls every close pair together, into the wall
    fit = bodies._fit

    def flipped(*args):
        model, seconds, what, saved = fit(*args)
        with torch.no_grad():
            model.coef.neg_()           # in its state_dict: the size's cell rebuilds it flipped
        return model, seconds, what, saved

    monkeypatch.setattr(bodies, "_fit", flipped)
    results = bodies.study(sizes=(8,), fits=("library",), seed=0, starts=1, dt=0.01, horizon=1.0, adam_steps=0,
                           hidden=8, scene="lj")
    row = results["rows"][0]
    # the pull grows smoothly as a pair closes, so the pair passes the wall's range 0.7 (a WallError from the true H
    # along the path) long before the step blows up
    assert "wall's range" in row["library"]["diverged"] and row["library"]["seconds_per_step"] > 0
    assert row["true"]["energy_per_body"] < 1e-2


def test_the_distances_read_are_the_interacting_pairs_block_by_block(monkeypatch):
    """Every pair once (blocks of 3 bodies against all: torch.pdist's distances), a chain's neighbours, a cutoff's
    pairs closer than it; and the shares outside a fitted range count each pair once."""
    import torch

    from hnn.bodies import Bodies
    monkeypatch.setattr(bodies, "DISTANCE_BLOCK", 3)
    x = torch.randn(2, 4 * 8, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    q, _ = Bodies(8, 2).split(x)
    every = torch.cat([torch.pdist(q[b]) for b in range(2)])
    got = bodies._distances(x, Bodies(8, 2))
    assert torch.allclose(got.sort().values, every.sort().values, rtol=0, atol=1e-14)
    chain = torch.linalg.vector_norm(q[:, 1:] - q[:, :-1], dim=-1).reshape(-1)
    assert torch.equal(bodies._distances(x, Bodies(8, 2, pairs="neighbours")).sort().values, chain.sort().values)
    near = bodies._distances(x, Bodies(8, 2, pairs="cutoff", cutoff=1.5))
    assert torch.allclose(near.sort().values, every[every < 1.5].sort().values, rtol=0, atol=1e-14)
    reach = bodies._reach(torch.tensor([0.5, 1.0, 2.0, 4.0]), (0.8, 3.0))
    assert reach == {"closest": 0.5, "farthest": 4.0, "below": 0.25, "beyond": 0.25}
    # a few pairs of millions are said, not rounded away
    assert [bodies._share(v) for v in (0.0, 3e-6, 0.0005, 0.25)] == ["0.0%", "<0.1%", "0.1%", "25.0%"]


def test_gravity_past_its_training_disk_has_pairs_farther_than_any_fitted():
    """The disk grows with N at the training's density: at N = 8 every start pair lies within the distances the
    fit saw, at 64 still, and at 512 a share of the pairs lies beyond them (read by extrapolation)."""
    results = bodies.study(sizes=(8, 512), fits=("library",), seed=0, starts=1, dt=0.01, horizon=0.01, adam_steps=0,
                           hidden=8, scene="gravity")
    small, large = (row["starts"] for row in results["rows"])
    assert small["beyond"] == 0.0 and small["below"] == 0.0
    assert large["beyond"] > 0.1 and large["farthest"] > results["settings"]["fitted_distances"][1]
    results["meta"] = {"command": "python analysis/bodies.py --scene gravity", "cores": 2, "cpu": "test"}
    assert "**Distances at the starts**" in bodies.table(results)


def test_a_fits_table_rolls_out_the_fits_paths_and_says_how_it_was_made():
    results = bodies.study(sizes=(8, 16), fits=("swim", "swim+table"), seed=0, starts=2, dt=0.1, horizon=1.0,
                           adam_steps=0, hidden=16)
    for row in results["rows"]:
        network, table = row["swim"], row["swim+table"]
        # the table's slopes are within TABLE_TOL (1e-5) of the network's: over 10 leapfrog steps the two paths part
        # by about that much of their size, far below the leapfrog's own error at dt = 0.1 that both errors carry
        assert table["rollout"] == pytest.approx(network["rollout"], rel=1e-3)
        assert table["energy_per_body"] == pytest.approx(network["energy_per_body"], rel=1e-3)
        assert table["seconds_per_step"] > 0
    made = results["fits"]["swim+table"]
    assert "as a table of" in made["what"] and made["max_error"] <= bodies.TABLE_TOL
    results["meta"] = {"command": "python analysis/bodies.py --quick", "cores": 2, "cpu": "test"}
    assert "**swim+table**" in bodies.table(results) and "s to tabulate)" in bodies.table(results)
    with pytest.raises(ValueError, match=r"tabulates the swim fit's model: study swim too"):
        bodies.study(sizes=(8,), fits=("swim+table",), seed=0, starts=1, dt=0.1, horizon=0.5, adam_steps=0, hidden=8)
