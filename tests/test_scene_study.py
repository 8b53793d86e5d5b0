"""The scene study's metrics against analytic truths, its model choice, and one tiny run end to end."""
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

import hnn
from hnn_analysis.paper import reproduce, study
from hnn_analysis.scenes import scene_measure, scene_metrics as sm, scene_report, scene_stages, scene_study, scene_tables, scene_common
from hnn_analysis.scenes import scene_rungs


def _spring_truth(x0, t, omega=2.0):
    """The exact flow of H = q^2 + p^2 (dq/dt = 2p, dp/dt = -2q): a rotation by omega t."""
    c, s = np.cos(omega * t), np.sin(omega * t)
    q0, p0 = x0[:, :1].numpy(), x0[:, 1:].numpy()
    return torch.tensor(np.stack([q0 * c + p0 * s, -q0 * s + p0 * c], axis=-1), dtype=torch.float64)


def test_rollout_error_of_a_detuned_oscillator_is_analytic(spring):
    # a model that turns (1 + eps) times as fast: |x' - x| / (|x'| + |x|) = |sin(eps omega t / 2)| exactly
    eps, omega = 0.02, 2.0
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.4]], dtype=torch.float64)
    t = np.linspace(0.0, 30.0, 601)
    truth = _spring_truth(x0, t)
    out = hnn.evaluation.rollout_errors(lambda x: (1 + eps) * spring.dynamics(x), truth, t)
    e = np.abs(np.sin(eps * omega * t[1:] / 2))
    assert out["error"] == pytest.approx(float(np.exp(np.log(e).mean())), rel=1e-5)
    first = 2 * math.asin(hnn.metrics.VALID_ERROR) / (eps * omega)           # the first time e(t) = 0.1
    assert first < out["valid_time"] <= first + (t[1] - t[0])
    assert out["horizon"] == 30.0 and out["blew_up"] == 0


def test_a_perfect_model_is_valid_for_the_whole_horizon_and_the_spring_never_diverges(spring):
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.5]], dtype=torch.float64)
    t = np.linspace(0.0, 10.0, 201)
    out = hnn.evaluation.rollout_errors(spring.dynamics, _spring_truth(x0, t), t)
    assert out["error"] < 1e-6 and out["valid_time"] == 10.0
    # a linear isochronous oscillator keeps a 1e-4 perturbation at 1e-4: no divergence
    assert sm.divergence_time(spring.dynamics, x0, t)["divergence_time"] == 10.0


def test_divergence_time_of_an_unstable_saddle_is_analytic():
    # dq/dt = q, dp/dt = -p (H = q p): from x0 = (0, 1) and x0 + d, the two exact paths are
    # (0, e^-t) and (dq e^t, (1 + dp) e^-t), so the time their relative error passes 0.1 is known
    x0 = torch.tensor([[0.0, 1.0]], dtype=torch.float64)
    t = np.linspace(0.0, 12.0, 1201)
    got = sm.divergence_time(lambda x: torch.stack([x[:, 0], -x[:, 1]], 1), x0, t)["divergence_time"]
    d = np.random.default_rng(0).standard_normal((1, 2))     # the direction divergence_time draws
    dq, dp = sm.PERTURBATION * d[0] / np.linalg.norm(d)
    ts = np.linspace(0.0, 12.0, 1_200_001)
    e = np.hypot(dq * np.exp(ts), dp * np.exp(-ts)) / (np.hypot(dq * np.exp(ts), (1 + dp) * np.exp(-ts)) + np.exp(-ts))
    exact = ts[np.argmax(e > hnn.metrics.VALID_ERROR)]
    assert exact < got <= exact + (t[1] - t[0]) + 1e-9


def test_speed_ladder_takes_the_first_setting_of_each_method_that_reaches_the_target(spring):
    x0 = torch.tensor([[1.0, 0.0], [0.2, 0.7]], dtype=torch.float64)
    t = np.linspace(0.0, 3.0, 31)
    ladder = sm.settings_ladder((0.5, 0.2, 0.1, 0.05, 0.02, 0.01), separable=True, quick=False)
    assert {o["method"] for o in ladder} >= {"leapfrog", "midpoint", "rk4", "dopri5", "solve_ivp"}
    assert not any(o["method"] == "leapfrog" for o in sm.settings_ladder((0.1,), separable=False, quick=False))
    result = sm.speed_at_accuracy(spring.dynamics, x0, t, ladder)
    ok = [r for r in result["rows"] if r["status"] == "ok"]
    # within one method, the steps tried shrink until one reaches the target, then stop
    for method in ("rk4", "leapfrog"):
        rows = [r for r in ok if r["options"]["method"] == method]
        assert all(r["error"] > sm.TARGET for r in rows[:-1]) and rows[-1]["error"] <= sm.TARGET
        assert [r["options"]["dt"] for r in rows] == sorted([r["options"]["dt"] for r in rows], reverse=True)
    assert result["fastest"]["error"] <= sm.TARGET
    assert result["fastest_symplectic"]["symplectic"]
    # leapfrog is second order, rk4 fourth: rk4 reaches 1e-4 at a coarser step
    dt = {m: [r for r in ok if r["options"]["method"] == m][-1]["options"]["dt"] for m in ("rk4", "leapfrog")}
    assert dt["rk4"] > dt["leapfrog"]


def test_speed_ladder_of_a_learned_h_picks_its_fastest_energy_preserving_setting():
    """A field that carries its H (an HNN) gets the discrete gradient in its ladder; the pick is the
    quickest setting of a solver that declares itself energy-preserving and reaches the target."""
    torch.manual_seed(0)
    f = hnn.build_model(2, 16).double().field
    x0 = torch.tensor([[1.0, 0.0], [0.2, 0.7]], dtype=torch.float64)
    t = np.linspace(0.0, 3.0, 31)
    ladder = sm.settings_ladder((0.5, 0.2, 0.1, 0.05, 0.02, 0.01), separable=False, quick=False, energy=True)
    assert any(o["method"] == "discrete_gradient" for o in ladder)
    assert not any(o["method"] == "discrete_gradient" for o in sm.settings_ladder((0.1,), False, False))
    result = sm.speed_at_accuracy(f, x0, t, ladder, repeats=1)
    pick = result["fastest_energy_preserving"]
    assert pick["options"]["method"] == "discrete_gradient" and pick["energy_preserving"]
    assert pick["error"] <= sm.TARGET and not pick["symplectic"]
    assert all(r["energy_preserving"] == (r["options"]["method"] == "discrete_gradient") for r in result["rows"])


def test_long_drift_of_rk4_on_the_oscillator_is_its_exact_amplification_factor(spring):
    # RK4 multiplies the energy of a harmonic oscillator by |R(i h omega)|^2 every step, exactly
    h, omega, periods = math.pi / 8, 2.0, 40            # 2 steps per output interval of pi / 4
    x0 = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    out = sm.long_drift(spring.dynamics, spring.hamiltonian, x0, {"method": "rk4", "dt": h}, math.pi, periods,
                        budget=60.0)
    z = 1j * h * omega
    factor = abs(1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24) ** 2
    assert out["periods_done"] == periods and not out["blew_up"]
    assert out["drift"] == pytest.approx(1 - factor ** (8 * periods), rel=1e-8)
    # leapfrog at the same step keeps the energy bounded: no secular drift from 10 to 40 periods
    lf = [sm.long_drift(spring.dynamics, spring.hamiltonian, x0, {"method": "leapfrog", "dt": h}, math.pi, n,
                        budget=60.0)["drift"] for n in (10, 40)]
    assert lf[1] == pytest.approx(lf[0], rel=1e-6) and lf[1] < 0.2


def test_long_drift_stops_at_its_budget_and_says_how_far_it_got(spring):
    x0 = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    out = sm.long_drift(spring.dynamics, spring.hamiltonian, x0, {"method": "rk4", "dt": 1e-3}, math.pi, 1000,
                        budget=0.0)
    assert out["periods_done"] < 1000 and out["periods"] == 1000


def _cell(params, energy, rollout, seconds=1.0):
    return {"params": params, "train_seconds": seconds, "energy_mse_corrected": [energy, 0.0],
            "rollout": {"error": rollout}}


def _one(params, energy, rollout, seconds=1.0):
    """A cell measured at seed 0 alone."""
    return {0: _cell(params, energy, rollout, seconds)}


def test_scene_card_picks_the_smallest_model_within_2x_of_both_bests():
    cells = {("hnn", 200, 1.0): _one(41200, 1e-4, 0.10),
             ("hnn", 16, 1.0): _one(352, 1.5e-4, 0.5),         # small, but 5x the best rollout error
             ("separable", 32, 0.5): _one(2300, 1.9e-4, 0.17),  # within 2x of both: the card
             ("baseline", 16, 1.0): _one(352, 1e-1, 0.09)}      # best rollout, far worse energy
    card = scene_stages.scene_card(cells)
    assert (card["kind"], card["width"], card["fraction"]) == ("separable", 32, 0.5)
    assert card["best_energy"] == 1e-4 and card["best_rollout"] == 0.09
    # one seed: the card tests nothing about seeds, and says so
    assert card["unsettled"] is None and scene_tables.unsettled(card) == "one seed: not tested"
    assert scene_stages.scene_card({("hnn", 200, 1.0): _one(1, 1.0, 1.0)})["kind"] == "hnn"


def test_scene_card_falls_back_to_the_model_nearest_both_bests():
    # the best energy and the best rollout come from two models, each far off on the other error:
    # nothing is within 2x of both, and the card names the smallest larger ratio (here 3x, not 10x)
    cells = {("mechanical", 16, 0.5): _one(500, 1e-5, 0.9),        # best energy, 10x the best rollout
             ("separable", 16, 1.0): _one(600, 1e-3, 0.09),        # best rollout, 100x the best energy
             ("hnn", 200, 1.0): _one(41200, 3e-5, 0.18),           # 3x and 2x: the nearest
             ("hnn", 32, 1.0): _one(1200, 4e-5, 0.3)}              # smaller, but 4x and 3.3x
    card = scene_stages.scene_card(cells)
    assert (card["kind"], card["width"]) == ("hnn", 200)
    assert card["within"] == pytest.approx(3.0)
    assert "none within 2x of both bests; nearest: hnn, width 200" in scene_tables.card_name(card)
    normal = scene_stages.scene_card({("hnn", 32, 1.0): _one(1200, 1e-4, 0.1)})
    assert normal["within"] == 1.0 and scene_tables.card_name(normal) == "hnn, width 32, 1 of the data"


def test_scene_card_chooses_on_seed_means_and_names_what_the_seeds_cannot_separate():
    seeds = lambda params, energies, rollouts: {s: _cell(params, e, r) for s, (e, r) in  # noqa: E731
                                                enumerate(zip(energies, rollouts))}
    cells = {("hnn", 200, 1.0): seeds(41200, [1e-4, 1e-4, 1e-4], [0.10, 0.10, 0.10]),     # the best means
             # seed 0 alone would make this tiny model the card (1.5x, 1.2x); its mean is 5x the best energy
             ("hnn", 16, 1.0): seeds(352, [1.5e-4, 6e-4, 8.5e-4], [0.12, 0.12, 0.12]),
             ("separable", 32, 0.5): seeds(2300, [1.2e-4, 1.5e-4, 2.7e-4], [0.15, 0.15, 0.15]),  # mean 1.8x
             ("baseline", 16, 0.25): seeds(300, [5e-3, 6e-3, 7e-3], [0.11, 0.11, 0.11])}  # every seed far off
    card = scene_stages.scene_card(cells)
    assert (card["kind"], card["width"], card["fraction"]) == ("separable", 32, 0.5)
    assert card["energy"] == pytest.approx(1.8e-4) and card["n_seeds"] == 3
    # the tiny HNN's seed 0 is within 2x of both bests: the seeds cannot separate it from the pick;
    # the baseline, smaller still, has no seed near the best energy
    assert card["unsettled"] == ["hnn, width 16, 1 of the data"]
    assert card["pick_straddles"] is True            # the pick's third seed is 2.7x the best energy
    assert scene_tables.unsettled(card) == "hnn, width 16, 1 of the data; some of the pick's own seeds are over 2x"
    # on seed 0 alone the card would have named the tiny HNN
    first = scene_stages.scene_card({k: {0: v[0]} for k, v in cells.items()})
    assert (first["kind"], first["width"]) == ("hnn", 16)


def test_scene_card_orders_models_of_equal_parameters_by_their_data_not_their_timing():
    seeds = lambda energies, seconds: {s: _cell(336, e, 0.1, seconds) for s, e in enumerate(energies)}  # noqa: E731
    best = {("hnn", 200, 1.0): {s: _cell(41200, 1e-4, 0.1) for s in range(3)}}
    # two cells of one width (equal parameters), both within 2x: the one on less data is the card, even
    # where the other happened to train faster in this sitting
    cells = {**best, ("mechanical", 16, 0.25): seeds([1.5e-4] * 3, 3.0),
             ("mechanical", 16, 0.5): seeds([1.2e-4] * 3, 2.0)}
    card = scene_stages.scene_card(cells)
    assert (card["kind"], card["width"], card["fraction"]) == ("mechanical", 16, 0.25)
    # a cell on a tenth of the data whose mean is over 2x but whose lowest seed is within it is smaller
    # than the pick however long it took to train, so the seeds cannot separate it
    cells[("mechanical", 16, 0.1)] = seeds([1.5e-4, 4e-4, 6e-4], 9.0)
    card = scene_stages.scene_card(cells)
    assert card["fraction"] == 0.25 and card["unsettled"] == ["mechanical, width 16, 0.1 of the data"]


def test_a_cards_timing_tie_break_and_its_seconds_are_the_median_of_its_seeds():
    # two kinds of equal parameters on equal data, both within 2x: the cheaper to train is the card. Seed 0's
    # timing says "a" (a burst that ran while the machine was quiet); the median of the three says "b"
    def timed(seconds):
        return {s: _cell(336, 1.2e-4, 0.1, t) for s, t in enumerate(seconds)}
    cells = {("hnn", 200, 1.0): {s: _cell(41200, 1e-4, 0.1) for s in range(3)},
             ("a", 16, 0.5): timed([1.0, 3.0, 3.2]), ("b", 16, 0.5): timed([2.0, 2.1, 1.9])}
    card = scene_stages.scene_card(cells)
    assert card["kind"] == "b" and card["train_seconds"] == 2.0
    assert scene_measure.median_cost_seconds(cells[("a", 16, 0.5)]) == 3.0
    # a cell whose seeds have no timing at all does not break the order
    assert scene_measure.median_cost_seconds({0: {"params": 1}}) is None


def test_a_card_names_the_cheapest_model_enough_and_the_libraries_enough_with_their_equations():
    seeds = lambda params, energy, seconds, equation=None: {  # noqa: E731
        s: {**_cell(params, energy, 0.1, seconds), **({"equation": equation} if equation else {})} for s in range(3)}
    cells = {("hnn", 200, 1.0): seeds(41200, 1e-4, 20.0),
             ("hnn+swim", 16, 1.0): seeds(65, 1.5e-4, 0.002),                      # the smallest and cheapest
             ("hnn+library", 200, 1.0): seeds(21, 1.2e-4, 0.01, "H = q^2 + p^2"),  # fewest parameters
             ("baseline+sindy", 200, 1.0): seeds(26, 5e-3, 0.02, "dq/dt = 2 p")}  # 50x the best energy: not enough
    card = scene_stages.scene_card(cells)
    assert card["kind"] == "hnn+library"                                           # fewest parameters first
    assert card["cheapest"]["kind"] == "hnn+swim" and card["cheapest"]["train_seconds"] == 0.002
    assert [lib["kind"] for lib in card["libraries"]] == ["hnn+library"]
    assert scene_tables.library_words(card) == "hnn+library (0.01 s): `H = q^2 + p^2`"
    assert scene_tables.cheapest_words(card) == "hnn+swim, width 16, 1 of the data (0.002 s)"
    # a card saved before the fits were rungs says so instead of failing
    assert scene_tables.library_words({}) == "not measured" and scene_tables.cheapest_words({}) == "not chosen"


def test_the_fits_rungs_keep_their_kinds_declarations():
    assert scene_rungs.fit_rungs(("hnn", "baseline", "mechanical"), ("hnn+swim", "hnn+library")) == [
        "hnn+swim", "hnn+library"]
    assert scene_rungs.fit_rungs(("mechanical",)) == []           # no fit of the studied rungs applies to it
    assert (scene_rungs.kind_of("hnn+swim"), scene_rungs.fit_of("hnn+swim"), scene_rungs.fit_of("hnn")) == (
        "hnn", "swim", "adam")
    assert scene_rungs.is_library("baseline+sindy") and not scene_rungs.is_library("hnn+swim")
    assert scene_tables.color("hnn+swim") == scene_tables.color("hnn") and scene_rungs.marker("hnn") == "o"
    assert "hnn+swim" in scene_common.task_rungs("spring") and "hnn+swim" not in scene_common.task_rungs("pixels")
    jobs = scene_rungs.jobs([{"row": "spring@200x1", "task": "spring", "fields": {}}], [0, 1], Path("runs"),
                            ("hnn", "hnn+library"), lambda task, rung: True)
    assert [(job.key, job.config.model, job.config.fit) for job in jobs] == [
        ("spring@200x1/hnn+library/seed0", "hnn", "library"), ("spring@200x1/hnn+library/seed1", "hnn", "library")]


def test_the_recorded_seeds_are_the_fewest_any_card_rests_on():
    results = {"meta": {"seeds": [0, 1, 2], "grid_seeds": [0, 1, 2]},
               "scenes": {"spring": {"card": {"n_seeds": 3}}, "real": {"card": None}}}
    assert (scene_report.seeds_of(results).count, scene_report.seeds_of(results).why) == (3, None)
    # a scene whose kinds trained at one seed picks its card from one seed, whatever --seeds says
    results["scenes"]["3body"] = {"card": {"n_seeds": 1}}
    seeds = scene_report.seeds_of(results)
    assert seeds.count == 1 and seeds.why.endswith("the cards of 3body (1) rest on fewer seeds")
    # a grid at seed 0 alone (--grid-seeds 1) is the fewest too, and the reason says so
    results = {"meta": {"seeds": [0, 1, 2], "grid_seeds": [0]}, "scenes": {"spring": {"card": {"n_seeds": 1}}}}
    assert scene_report.seeds_of(results).count == 1
    assert "grid trained at 1 seed" in scene_report.seeds_of(results).why


def test_kinds_the_seeds_cannot_separate_overlap_the_best_kinds_range():
    per_kind = {"hnn": {s: _cell(1, e, 0.1) for s, e in enumerate([1e-4, 2e-4, 3e-4])},
                "separable": {s: _cell(1, e, 0.2) for s, e in enumerate([2.5e-4, 4e-4, 5e-4])},    # overlaps
                "baseline": {s: _cell(1, e, 0.05) for s, e in enumerate([1e-2, 2e-2, 3e-2])}}      # apart
    tie = scene_stages.inseparable(per_kind)
    assert tie["energy"] == {"best": "hnn", "tied": ["separable"]}
    assert tie["rollout"] == {"best": "baseline", "tied": []}
    assert scene_stages.inseparable({k: {0: v[0]} for k, v in per_kind.items()}) == {}    # one seed: untested
    lines = scene_tables.inseparable_lines({"scenes": {"spring": {"inseparable": tie}}})
    assert lines[-1] == ("- spring: energy: best hnn, the seeds cannot separate separable; "
                         "rollout: best baseline, the seeds cannot separate no other kind")


def test_dhnn_split_uses_central_differences_on_their_rows():
    real = hnn.load_task("real")
    t, x = real.load_measurements()
    data = real.get_dataset(split="dhnn")
    assert len(data["x"]) == int(len(t) * 0.8) and len(data["x"]) + len(data["test_x"]) == len(t) - 1
    np.testing.assert_allclose(data["x"][:5], x[1:6].astype(np.float32))
    # where the samples are evenly spaced the mean of the two one-sided slopes is the central difference
    i = next(i for i in range(1, len(t) - 1) if abs((t[i + 1] - t[i]) - (t[i] - t[i - 1])) < 1e-9)
    central = (x[i + 1] - x[i - 1]) / (t[i + 1] - t[i - 1])
    np.testing.assert_allclose(data["dxdt"][i - 1], central, rtol=1e-5)
    with pytest.raises(ValueError, match="unknown split"):
        real.get_dataset(split="other")


def test_dhnn_protocol_scores_the_true_field_of_a_frictionless_pendulum_as_it_should():
    # a "model" whose field is the D-HNN paper's own H (k = 2.4), scored against scipy called directly
    real = hnn.load_task("real")
    data = real.get_dataset(split="dhnn")

    class TrueH(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.w = torch.nn.Parameter(torch.zeros(1))

        def time_derivative(self, x):
            q, p = x[:, 0], x[:, 1]
            return torch.stack([2 * p, -2.4 * torch.sin(q)], 1) + 0 * self.w

    out = sm.dhnn_protocol(real, {"h": TrueH()}, data)["h"]
    # the same rollout straight from scipy, with solve_ivp's defaults as their notebook called it
    from scipy.integrate import solve_ivp
    t = data["test_t"] - data["test_t"][0]
    sol = solve_ivp(lambda _, y: [2 * y[1], -2.4 * np.sin(y[0])], (0, t[-1]), data["test_x"][0].astype(float), t_eval=t)
    e_model = 2.4 * (1 - np.cos(sol.y[0])) + sol.y[1] ** 2
    e_true = real.hamiltonian(data["test_x"].astype(float))
    assert out["energy_mse"][0] == pytest.approx(float(np.mean((e_model - e_true) ** 2)), rel=1e-6)
    expected = np.mean((np.stack([2 * data["test_x"][:, 1], -2.4 * np.sin(data["test_x"][:, 0])], 1)
                        - data["test_dxdt"]) ** 2)
    assert out["test_mse"][0] == pytest.approx(float(expected), rel=1e-5)


def test_reproduce_models_flag_adds_kinds_only_where_a_task_has_them(tmp_path):
    jobs = study.plan(study.table_rows(["spring", "pixels"], quick=True), [0], tmp_path, None, ("separable",))
    assert [(job.key, job.config.kind) for job in jobs] == [
        ("spring/baseline/seed0", "baseline"), ("spring/hnn/seed0", "hnn"), ("spring/separable/seed0", "separable"),
        ("pixels/baseline/seed0", "pixel-baseline"), ("pixels/hnn/seed0", "pixel-hnn")]
    assert study.row_models("spring", ("dissipative",)) == ["baseline", "hnn", "dissipative"]
    assert study.row_models("pixels", ("separable", "dissipative")) == ["baseline", "hnn"]
    with pytest.raises(SystemExit):
        reproduce._parser().parse_args(["--models", "bogus"])


@pytest.mark.slow
def test_a_tiny_scene_study_end_to_end(tmp_path, monkeypatch):
    monkeypatch.setattr(scene_stages, "QUICK_WIDTHS", (8, 200))
    monkeypatch.setattr(scene_stages, "QUICK_FRACTIONS", (0.5, 1.0))
    monkeypatch.setattr(scene_stages, "QUICK_STEPS", 20)
    results = scene_study.main(["--quick", "--scenes", "spring", "--out", str(tmp_path)])
    entry = results["scenes"]["spring"]
    assert results["meta"]["rollout_seconds"] == scene_measure.QUICK_ROLLOUT_SECONDS
    assert results["meta"]["rollout_calls"] == scene_measure.QUICK_ROLLOUT_CALLS
    # the quick kinds and the fits' rungs over them (scene_rungs); the grid holds the quick grid's at 3 cells
    rungs, grid_rungs = scene_stages.rungs_of(True)
    assert set(entry["kinds"]) == set(rungs) & set(scene_common.task_rungs("spring"))
    assert len(entry["grid"]) == len(set(grid_rungs) & set(scene_common.task_rungs("spring"))) * 3
    assert entry["card"] is not None and entry["card"]["cheapest"] is not None
    assert all("train_cost" in m for m in entry["grid"].values())
    assert set(entry["speed"]) == set(scene_stages.QUICK_SPEED_KINDS) and entry["speed"]["hnn"]["fastest"] is not None
    # every unit's measuring seconds, by kind and grid, what the plan's declared costs are set from
    units = results["seconds"]["units"]
    assert set(units) == {f"kind spring {k}" for k in entry["kinds"]} | {f"cells spring {k}" for k in
                                                                          set(grid_rungs) & set(entry["kinds"])}
    assert all(0 < s <= results["seconds"]["measure"] for s in units.values())
    assert 0 < results["seconds"]["sweep"] < results["seconds"]["training"]
    saved = json.loads((tmp_path / "scene_study.json").read_text())
    assert saved["scenes"]["spring"]["card"] == json.loads(json.dumps(entry["card"]))
    text = (tmp_path / "scene_study.md").read_text()
    assert "QUICK smoke run" in text and "Scene cards" in text
    assert (tmp_path / "figures" / "scenes-pareto.png").stat().st_size > 10_000


def test_models_measured_together_get_the_numbers_each_gets_alone(tmp_path):
    # runs trained as one group (hnn.trainers.closed_form), measured as the study's grid is: one energy call for all
    configs = [hnn.tasks.task_config("spring", {"seed": s, "train_fraction": f, "hidden_dim": 16, "total_steps": 30,
                                                "save_dir": str(tmp_path)}) for s, f in ((0, 1.0), (1, 0.5), (2, 1.0))]
    folders = hnn.sweeps.group_runs.train_group(configs)
    scene = scene_common.Scene("spring", quick=True)
    together = scene_measure.measure_models(scene, {i: ("hnn", folder) for i, folder in enumerate(folders)})
    rebuilt = scene_common.Scene("spring", quick=True, state=scene.state())     # a worker's copy of the truth
    assert torch.equal(rebuilt.truth, scene.truth) and rebuilt.divergence == scene.divergence
    for i, folder in enumerate(folders):
        alone = rebuilt.measure("hnn", folder)
        for key in ("energy_mse_paper", "energy_mse_corrected", "test_loss", "params"):
            assert together[i][key] == alone[key], key
        for key in ("error", "valid_time", "blew_up"):
            assert together[i]["rollout"][key] == alone["rollout"][key], key
        cost = together[i]["train_cost"]
        assert cost["steps"] == 31 and cost["seconds"] == pytest.approx(31 / cost["steps_per_s"])
    # the models differ: equal numbers above are not one model's numbers copied
    assert len({m["energy_mse_corrected"][0] for m in together.values()}) == 3


def test_every_scene_has_kinds_and_the_pixel_scene_measures_its_own_pair():
    # a pixel model reads frames through its encoder: its scene keeps the paper's pair
    assert set(scene_common.task_kinds("pixels")) == {"baseline", "hnn"}
    for task in scene_common.scenes():
        assert scene_common.task_kinds(task), f"the {task} scene has no kind"
    # a kind that reads [q, qdot] does not fit a scene of [q, p]
    assert "second_order" not in scene_common.task_kinds("spring")


def test_quick_grids_one_narrow_cell_with_fewer_steps_and_says_every_cut(tmp_path):
    rows = scene_stages.plan_rows(["spring", "real"], quick=True)
    grid = [row for row in rows if row["cell"] != scene_stages.DEFAULT_CELL]
    # the grid scenes only (spring), at one narrow cell: the grid stage runs, on little
    assert [(row["task"], row["cell"]) for row in grid] == [("spring", (16, 0.25))]
    jobs = study.plan(rows, [0], tmp_path, scene_stages.QUICK_STEPS)
    assert {job.config.total_steps for job in jobs} == {scene_stages.QUICK_STEPS} and scene_stages.QUICK_STEPS == 60
    cuts = scene_stages.quick_cuts(["spring", "pixels"], seeds=3)
    assert cuts[0] == "60 training steps a model of the tasks' own 2000 (spring), 10000 (pixels)"
    assert "pixels: trials 20 of 200" in cuts and "energy MSE: 5 trials of each protocol's 15" in cuts
    assert "1 seed of 3, the grid's as the default cell's, so the cards test nothing on seeds" in cuts
    assert "grid: widths 16 x fractions 0.25 of 16, 32, 64, 128, 200 x 0.1, 0.25, 0.5, 1.0" in cuts
    assert any(cut.startswith("speed at accuracy: the hnn kind only") for cut in cuts)
    assert "energy drift: 3 periods of 1000 (spring), at most 0.5 s a setting of 15" in cuts
    # a fit on a few rows, a rollout within its budget (a stiff one stops there and says so): each cut is said
    assert f"fits: at most {scene_stages.QUICK_FIT_ROWS} training rows each (a cell's fraction of them where that is " \
           "fewer); a fit's training cost is the solve its run recorded, not solved again" in cuts
    assert any(cut.startswith(f"rollouts of the models: at most {scene_measure.QUICK_ROLLOUT_SECONDS:g} s each on "
                              f"the reference box, {scene_measure.QUICK_ROLLOUT_CALLS} field calls") for cut in cuts)
    # fewer kinds, one scene's speed study, a scene whose dataset is dear left out: each said
    assert any(cut.startswith("kinds: baseline, hnn, hnn+swim, hnn+library") and cut.endswith("on the grid hnn, hnn+swim")
               for cut in cuts)
    assert scene_stages.quick_scenes(["spring", "pixels"]) == ["spring"]
    assert any(cut.startswith("scenes: pixels left out") for cut in scene_stages.quick_cuts(["spring"], 3, 1, ["pixels"]))
    # the speed study runs for the quick kinds only; every kind is still measured
    runs = {f"spring@200x1/{kind}/seed0": tmp_path for kind in scene_common.task_kinds("spring")}
    units = scene_stages.measure_units(["spring"], runs, [0], [], [0], scene_stages.QUICK_SPEED_KINDS)
    assert {key[2]: unit[4] for key, unit in units.items()} == {kind: 0 if kind == "hnn" else None
                                                                 for kind in scene_common.task_kinds("spring")}
    # the grid is measured at each of its seeds, a run apiece; a seed that failed to train is left out
    runs.update({f"spring@16x0.25/hnn/seed{seed}": tmp_path / str(seed) for seed in (0, 2)})
    units = scene_stages.measure_units(["spring"], runs, [0], grid, [0, 1, 2])
    assert units[("cells", "spring", "hnn")][2] == {f"hnn@16x0.25/seed{seed}": ("hnn", str(tmp_path / str(seed)))
                                                      for seed in (0, 2)}
    # a quick scene's energy protocols run 5 trials of their 15
    assert scene_common.Scene("real", quick=True).trials == study.QUICK_TRIALS == 5
    assert scene_common.Scene("real", quick=False).trials is None
