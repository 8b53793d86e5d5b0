"""DGNet's objective: with the true H its loss is the analytic finite-difference residual of the
discrete gradient, it learns the spring from consecutive states alone, and it runs from the flags."""
import numpy as np
import pytest
import torch

import hnn
from hnn.objectives.dgnet import pairs_from_paths


class _TrueSpring(hnn.Model):
    """The repo's spring, H = q^2 + p^2, as a model (no weights to learn but one unused)."""
    conservative = True
    input_dim = 2

    def __init__(self):
        super().__init__()
        self.unused = torch.nn.Parameter(torch.zeros(()))

    def hamiltonian(self, x):
        return x[:, 0] ** 2 + x[:, 1] ** 2

    def time_derivative(self, x, t=None):
        return torch.stack([2 * x[:, 1], -2 * x[:, 0]], 1)


def test_with_the_true_h_the_loss_is_the_analytic_finite_difference_residual():
    # the spring turns x by the angle 2 dt; (x1 - x0)/dt and S grad-bar H = 2 J (x0 + x1)/2 (H is quadratic,
    # so any symmetric discrete gradient is grad H at the midpoint) are parallel, of lengths
    # 2 |x0| sin(dt)/dt and 2 |x0| cos(dt): the squared residual per component is 2 |x0|^2 (sin(dt)/dt - cos(dt))^2
    dt = 0.3
    gen = torch.Generator().manual_seed(0)
    x0 = torch.randn(40, 2, dtype=torch.float64, generator=gen)
    c, s = np.cos(2 * dt), np.sin(2 * dt)
    x1 = torch.stack([x0[:, 0] * c + x0[:, 1] * s, x0[:, 1] * c - x0[:, 0] * s], 1)
    pairs = torch.cat([x0, x1], 1)
    loss = hnn.objectives.dgnet.DiscreteGradientObjective(dt=dt).loss_for(_TrueSpring().double())(pairs, pairs).mean(1)
    expected = 2 * x0.pow(2).sum(1) * (np.sin(dt) / dt - np.cos(dt)) ** 2
    torch.testing.assert_close(loss, expected, rtol=1e-10, atol=1e-16)
    assert expected.min() > 1e-5        # not a vacuous zero at this dt


def test_pairs_are_every_consecutive_pair_of_each_path():
    rows = np.arange(12.0).reshape(6, 2)            # two paths of three states
    np.testing.assert_array_equal(pairs_from_paths(rows, 3),
                                  [[0, 1, 2, 3], [2, 3, 4, 5], [6, 7, 8, 9], [8, 9, 10, 11]])
    with pytest.raises(ValueError, match="not whole paths of 4 states"):
        pairs_from_paths(rows, 4)


def test_the_real_pendulums_pairs_never_span_a_gap_in_its_measurements():
    from hnn_analysis.chains import dgnet_protocol
    data = dgnet_protocol.dataset("real", 0)
    t, dt = data["t"], data["dt"]
    gaps = int((~np.isclose(np.diff(t), dt)).sum())
    assert gaps == 11            # 8 gaps of 1/3 s, 2 of 1/2 s, and the 18.5 s test block (the shipped file)
    assert len(data["pairs"]) == len(t) - 1 - gaps
    # each pair's second state is the row one dt after its first
    at = {tuple(row): i for i, row in enumerate(data["x"])}
    later = np.array([t[at[tuple(p[2:])]] - t[at[tuple(p[:2])]] for p in data["pairs"]])
    np.testing.assert_allclose(later, dt, rtol=1e-9)
    assert len(data["test_pairs"]) == len(data["test_t"]) - 1      # the test block has no gap


def test_it_learns_the_spring_from_consecutive_states_alone():
    spring = hnn.load_task("spring")
    objective = hnn.objectives.dgnet.DiscreteGradientObjective()
    data = objective.prepare(spring.get_dataset(seed=0, noise_std=0.0))
    torch.manual_seed(0)
    model = hnn.build_model(2, 32)
    tx, tdx = torch.as_tensor(data["test_x"]), torch.as_tensor(data["test_dxdt"])
    with torch.no_grad():
        before = float((model.time_derivative(tx) - tdx).pow(2).mean())
    pairs = torch.as_tensor(data["pairs"])
    hnn.train(model, pairs, pairs, total_steps=150, learn_rate=3e-3, loss=objective.loss_for(model, float(data["dt"])),
              progress=False)
    with torch.no_grad():
        after = float((model.time_derivative(tx) - tdx).pow(2).mean())
    # 0.81 at init (measured); the true time derivatives are never seen in training
    assert after < 1e-2 * before, (before, after)


def test_it_runs_from_the_flags_and_refuses_a_kind_without_h(tmp_path):
    trainer = hnn.load_task("spring", "train")
    run = trainer.main(["--objective", "discrete_gradient", "--total_steps", "3", "--hidden_dim", "8",
                        "--save_dir", str(tmp_path)])
    _, saved, metrics = hnn.load_run(run)
    assert saved["objective"] == "discrete_gradient" and np.isfinite(metrics["test_loss"]) and metrics["test_loss"] > 0
    with pytest.raises(ValueError, match="carries none.*choose a conservative kind"):
        trainer.main(["--objective", "discrete_gradient", "--model", "baseline", "--total_steps", "1",
                      "--hidden_dim", "8", "--save_dir", str(tmp_path)])
    with pytest.raises(ValueError, match="needs paths"):
        hnn.objectives.dgnet.DiscreteGradientObjective().prepare({"x": np.zeros((4, 2)), "test_x": np.zeros((4, 2))})


def test_the_protocol_table_puts_every_published_row_beside_ours(tmp_path):
    from hnn_analysis.chains import dgnet, dgnet_protocol

    results = dgnet.main(["--steps", "2", "--seeds", "1", "--tasks", "spring", "real", "--out", str(tmp_path)])
    text = (tmp_path / "dgnet.md").read_text()
    for task in ("spring", "real"):
        assert f"### {task}" in text
        assert set(results["rows"][task]) == set(dgnet_protocol.rows_for(task))
        for label, runs in results["rows"][task].items():
            energies = runs[0]["energy"]
            assert set(energies) == set(dgnet_protocol.ROWS[label][3]) and all(np.isfinite(v) for v in energies.values())
    # the real pendulum has no true dx/dt: the paper's objective row is not run there
    assert "HNN, paper's objective" not in results["rows"]["real"]
    assert "| DGNet (discrete gradient / discrete gradient) | 1.38e-03 | 5.04e-04 | published, mean of 15 |" in text
    # their code starts every model's MLP with zero biases (dgnet/ode.py reset_parameters): ours too, said
    assert text.count("every MLP started with orthogonal weights and zero biases (theirs)") == 2
    assert all(r["train_seconds"] > 0 for runs in results["rows"]["real"].values() for r in runs)
    assert text.count("runs trained for") == 2
    model, saved, _ = hnn.load_run(results["rows"]["spring"]["DGNet"][0]["run"])
    assert saved["init"] == "zero_bias"
    torch.manual_seed(0)
    assert not hnn.kinds.model_from_args(saved).differentiable_model.linear1.bias.any()
    # --update-docs writes one section per task it ran (each with its stamp), so the others stay
    from hnn_analysis import pages
    section = dgnet_protocol.task_table(results, "real")
    assert section.startswith("### real") and "--tasks spring real" in section and "### spring" not in section
    for task in dgnet_protocol.TASKS:
        assert pages.PAGES[f"dgnet-{task}"] == "docs/dgnet.md" and pages.section_text(f"dgnet-{task}") is not None
    # the data: every consecutive pair of the 25 training paths of 100 states, at their dt = 20/99
    data = dgnet_protocol.dataset("spring", 0)
    assert data["pairs"].shape == (25 * 99, 4) and data["dt"] == pytest.approx(20 / 99)
    np.testing.assert_array_equal(data["pairs"][0], np.concatenate([data["x"][0], data["x"][1]]))


def test_the_2body_data_is_their_recipe_cut_into_consecutive_pairs():
    from hnn_analysis.chains import dgnet_protocol
    data = dgnet_protocol.dataset("2body", 0)
    # 1000 orbits of 500 states on [0, 25]: the first 200 orbits test, 800 train; width 8, no noise
    assert data["x"].shape == data["dxdt"].shape == (800 * 500, 8)
    assert data["test_x"].shape == data["test_dxdt"].shape == (200 * 500, 8)
    assert data["dt"] == pytest.approx(25 / 499) and len(data["t_eval"]) == 500 and data["t_eval"][-1] == 25.0
    assert data["pairs"].shape == data["snippets"].shape == (800 * 499, 16)
    assert data["test_pairs"].shape == (200 * 499, 16)
    # pairs are consecutive states of one orbit, never across two orbits
    x, pairs = data["x"], data["pairs"]
    for k, n in ((0, 0), (498, 498), (499, 500), (len(pairs) - 1, len(x) - 2)):
        np.testing.assert_array_equal(pairs[k], np.concatenate([x[n], x[n + 1]]))
    # the original's draws in order: seed 0's first orbit starts at their first energy trial's state
    system = hnn.load_task("2body")
    np.testing.assert_allclose(data["test_x"][0], system.initial_state(0), rtol=1e-6)
    np.testing.assert_allclose(data["test_dxdt"][:500], system.dynamics(torch.as_tensor(data["test_x"][:500],
                                                                                         dtype=torch.float64)),
                               rtol=1e-5, atol=1e-6)
    assert dgnet_protocol.SETTINGS["2body"] == {"steps": 10000, "batch_size": 200, "weight_decay": 0.0}


def test_the_2body_table_puts_every_published_row_beside_ours(tmp_path, monkeypatch):
    from hnn_analysis.chains import dgnet, dgnet_protocol
    monkeypatch.setitem(dgnet_protocol.TWO_BODY, "num_trials", 10)       # 8 training orbits: seconds, not minutes
    results = dgnet.main(["--steps", "2", "--seeds", "1", "--tasks", "2body", "--out", str(tmp_path)])
    text = (tmp_path / "dgnet.md").read_text()
    assert "### 2body" in text and "2 steps a run (theirs: 10000) of minibatches of 200" in text
    for name, (d, e) in dgnet_protocol.PUBLISHED["2body"].items():
        assert f"| {name} | {d:.2e} | {e:.2e} | published, mean of 15 |" in text
    assert set(results["rows"]["2body"]) == set(dgnet_protocol.rows_for("2body")) and len(dgnet_protocol.rows_for("2body")) == 5
    for label, runs in results["rows"]["2body"].items():
        assert np.isfinite(runs[0]["derivative"])
        assert set(runs[0]["energy"]) == set(dgnet_protocol.ROWS[label][3])
        assert all(np.isfinite(v) for v in runs[0]["energy"].values())
        for predict in dgnet_protocol.ROWS[label][3]:
            assert f"| ours: {label} ({dgnet_protocol.ROWS[label][2]} / {predict}) |" in text
        _, saved, _ = hnn.load_run(runs[0]["run"])
        assert (saved["batch_size"], saved["total_steps"], saved["weight_decay"]) == (200, 2, 0.0)


def test_quick_runs_every_row_of_every_task_on_one_seed_and_few_steps_and_says_so(tmp_path, monkeypatch, capsys):
    from hnn_analysis.chains import dgnet, dgnet_protocol
    asked = []

    def fake_job(args):      # what a run would be asked, without training it
        task, label, seed, steps, out, init, quick, device = args
        assert device == "cpu"
        asked.append((task, label, seed, steps, quick))
        return (*args[:3], init), {"run": "", "derivative": 1.0,
                                   "energy": {p: 1.0 for p in dgnet_protocol.ROWS[label][3]}}

    monkeypatch.setattr(dgnet, "measure_job", fake_job)
    results = dgnet.main(["--quick", "--out", str(tmp_path)])
    assert sorted(asked) == sorted((task, label, 0, dgnet_protocol.QUICK["steps"], True) for task in dgnet_protocol.TASKS
                                   for label in dgnet_protocol.rows_for(task))
    out = capsys.readouterr().out
    assert "--quick: every stage on small settings, within a budget of 120 s" in out
    assert "  - 1 seed of their 15 trials" in out and "100 steps a run of their 2000 (spring)" in out
    assert "10000 (2body)" in out and f"[{len(asked)}/{len(asked)}, " in out
    assert "  - 10 paths of their 50 (spring, pend)" in out and "  - 100 orbits of their 1000 (2body)" in out
    assert (tmp_path / "dgnet.md").read_text().startswith("**QUICK smoke run**")
    assert results["meta"]["quick"] and results["seeds"] == 1
    # a seed count or steps given with --quick are kept, and not listed as cut
    asked.clear()
    dgnet.main(["--quick", "--seeds", "2", "--tasks", "real", "--out", str(tmp_path)])
    assert {seed for _, _, seed, _, _ in asked} == {0, 1} and "seed of their" not in capsys.readouterr().out
    with pytest.raises(SystemExit):
        dgnet.main(["--quick", "--update-docs"])


def test_compare_init_trains_the_rows_asked_from_both_inits_and_tells_them_apart_on_seeds(tmp_path, monkeypatch):
    from hnn_analysis.chains import dgnet, dgnet_init, dgnet_protocol
    asked = []

    def fake_job(args):      # DGNet's energies: 10x lower from zero biases; the HNN's: the same from both
        task, label, seed, steps, out, init, quick, device = args
        asked.append((label, seed, init))
        scale = 0.1 if (label == "DGNet" and init == "zero_bias") else 1.0
        return (*args[:3], init), {"run": "", "derivative": 1.0, "energy": {
            p: scale * (1.0 + 0.1 * seed) for p in dgnet_protocol.ROWS[label][3]}}

    monkeypatch.setattr(dgnet, "measure_job", fake_job)
    results = dgnet.main(["--quick", "--tasks", "spring", "--seeds", "4", "--rows", "DGNet", "HNN", "--compare-init",
                          "--out", str(tmp_path)])
    assert sorted(asked) == sorted((label, seed, init) for label in ("HNN", "DGNet") for seed in range(4)
                                   for init in dgnet_init.INITS)
    text = (tmp_path / "dgnet-init.md").read_text()      # beside the tables' dgnet.md, not over it
    # 4 seeds against 4, every zero-bias seed below every default-bias one: the exact two-sided p is 2/70
    assert "| DGNet (discrete gradient / discrete gradient) |" in text and "| 0.029 | zero biases lower |" in text
    assert "| HNN (RK4 step / ada. DP) |" in text and "the seeds cannot separate them" in text
    assert set(results["init_rows"]["spring"]) == {"DGNet", "HNN"}
    # a task's table with rows missing is never written to the page
    with pytest.raises(SystemExit):
        dgnet.main(["--tasks", "spring", "--rows", "DGNet", "--update-docs"])
    with pytest.raises(SystemExit):
        dgnet.main(["--tasks", "real", "--compare-init", "--update-docs"])


def test_the_init_verdict_needs_three_seeds_a_side_and_a_separating_rank_test():
    from hnn_analysis.chains import dgnet_init
    assert dgnet_init.compare([1.0, 2.0], [3.0, 4.0]) == (None, "too few seeds to test")
    p, verdict = dgnet_init.compare([5.0, 6.0, 7.0, 8.0, 9.0], [1.0, 2.0, 3.0, 4.0, 4.5])
    assert verdict == "default biases lower" and p == pytest.approx(2 / 252)      # exact: 2 of C(10, 5) orders
    p, verdict = dgnet_init.compare([1.0, 3.0, 5.0], [2.0, 4.0, 6.0])
    assert verdict == "the seeds cannot separate them" and p > dgnet_init.P_SEPARATE


def test_quick_data_are_their_recipe_on_fewer_paths_and_orbits():
    from hnn_analysis.chains import dgnet_protocol
    quick, full = dgnet_protocol.dataset("spring", 0, **dgnet_protocol.QUICK_DATA), dgnet_protocol.dataset("spring", 0)
    # half the paths train, as theirs: 5 of 10 paths of 100 states, every consecutive pair
    assert quick["pairs"].shape == (5 * 99, 4) and full["pairs"].shape == (25 * 99, 4)
    assert quick["dt"] == full["dt"]
    orbits = dgnet_protocol.dataset("2body", 0, orbits=10)
    assert len(orbits["pairs"]) == 8 * 499         # 80% of the orbits train, each 500 states


def test_the_table_counts_our_seeds_below_their_published_mean_of_the_same_row():
    from hnn_analysis.chains import dgnet_protocol
    theirs = dgnet_protocol.published_energy("spring", "DGNet", "discrete gradient")
    assert theirs == dgnet_protocol.PUBLISHED["spring"]["DGNet (discrete gradient / discrete gradient)"][1]
    assert dgnet_protocol.published_energy("spring", "HNN, paper's objective", "ada. DP") is None   # no row of theirs
    runs = [{"derivative": 0.04, "energy": {p: e for p in ("discrete gradient", "ada. DP", "leapfrog")}}
            for e in (0.5 * theirs, 0.9 * theirs, 2.0 * theirs)]
    results = {"seeds": 3, "steps": {"spring": 2000}, "meta": {"command": "cmd", "seconds": 1.0, "cores": 2},
               "tasks": ["spring"], "init": "zero_bias",
               "rows": {"spring": {label: runs for label in dgnet_protocol.rows_for("spring")}}}
    text = dgnet_protocol.task_table(results, "spring")
    assert "| ours, mean of 3 seeds, 2000 steps | 2 of 3 |" in text
    assert text.splitlines()[-1].endswith("| ours, mean of 3 seeds, 2000 steps |  |")    # the paper's objective
    # a table published from saved runs still says what their training cost, summed from each run's metrics
    assert "runs trained for" not in text                       # these records carry no training seconds
    timed = [{**r, "train_seconds": 2.0} for r in runs]
    results["rows"]["spring"] = {label: timed for label in dgnet_protocol.rows_for("spring")}
    n_runs = 3 * len(results["rows"]["spring"])
    assert f"; its {n_runs} runs trained for {2 * n_runs} s in all" in dgnet_protocol.task_table(results, "spring")
