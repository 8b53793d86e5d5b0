"""Your own measurements (experiment-measured/, analysis/scenes/measured_*.py): reading, differences,
angles, scaling, the right kind on a synthetic damped oscillator, one error line per bad input."""
import hashlib
import json
import math
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import hnn
from hnn_analysis.scenes import scoring as score
from hnn_analysis.paper import study
from hnn_analysis.scenes import measured_card, measured_metrics as mm, measured_study, scene_study

REPO = Path(__file__).resolve().parent.parent
SYSTEMS = REPO / "experiment-measured" / "systems"
data = hnn.load_task("measured")
reader = hnn.load_task("measured", "reader")
train = hnn.load_task("measured", "train")
# the digests of the archive members (invar_datasets.zip of Schmidt & Lipson 2009), computed from the archive
PUBLISHED = {"real_linear_h_1.txt": "bf11e50703376b82566b635771de23845a2546e4b733beb49588c7af4eec26cc",
             "real_double_linear_h_1.txt": "b258df76a9a6f3dda294feb344160e39ecd3158d8e44b8bfe4ae4aa842c026aa"}


def _write_csv(path: Path, columns: dict) -> Path:
    names = list(columns)
    rows = np.stack([np.asarray(columns[n], dtype=float) for n in names], axis=1)
    path.write_text(",".join(names) + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in rows) + "\n")
    return path


def _damped(trials: int = 3, n: int = 160, gamma: float = 0.25, omega: float = 2.0, seed: int = 0) -> dict:
    """x'' = -omega^2 x - 2 gamma x' from random starts, exactly (its analytic solution), on uneven times."""
    rng = np.random.default_rng(seed)
    cols = {"run": [], "time": [], "x": [], "v": []}
    w = math.sqrt(omega ** 2 - gamma ** 2)
    for k in range(trials):
        t = np.cumsum(rng.uniform(0.04, 0.06, n))
        a, b = rng.uniform(-1, 1, 2) + np.array([1.0, 0.0])
        x = np.exp(-gamma * t) * (a * np.cos(w * t) + b * np.sin(w * t))
        v = np.exp(-gamma * t) * ((-gamma * a + w * b) * np.cos(w * t) + (-gamma * b - w * a) * np.sin(w * t))
        cols["run"] += [k] * n
        cols["time"] += list(t)
        cols["x"] += list(3.0 * x)          # a position unit that is not the velocity's: the scale must cope
        cols["v"] += list(3.0 * v)
    return cols


# ----------------------------------------------------------------------------------------------
# the shipped files


def test_the_shipped_real_systems_are_the_published_bytes_and_read_as_the_archive_means():
    for name, digest in PUBLISHED.items():
        assert hashlib.sha256((SYSTEMS / name).read_bytes()).hexdigest() == digest, name
        assert digest in (SYSTEMS / "DATA.md").read_text()
    table = reader.read_table(SYSTEMS / "real_linear_h_1.txt")
    assert table.names == ["trial", "t", "x", "v"] and table.values.shape == (870, 4)
    rec = data.load(SYSTEMS / "real_double_linear_h_1.txt", q="x1,x2", v="v1,v2", trial="trial")
    assert rec.q.shape == (495, 2) and rec.state == "velocity" and rec.t[0] == pytest.approx(0.033)


# ----------------------------------------------------------------------------------------------
# differences, angles, scale


def test_uneven_steps_and_a_gap_are_differenced_to_second_order_against_the_analytic_derivative():
    def worst(step: float) -> tuple[float, np.ndarray, np.ndarray]:
        rng = np.random.default_rng(1)
        t = np.cumsum(rng.uniform(0.5, 1.5, int(6 / step)) * step)
        t[len(t) // 2:] += 1.0               # a gap of ~1 s, far above 3 nominal steps
        x = np.stack([np.sin(2 * t), np.exp(-t) * np.cos(t)], axis=1)
        exact = np.stack([2 * np.cos(2 * t), -np.exp(-t) * (np.cos(t) + np.sin(t))], axis=1)
        dxdt, ok = data.derivatives(t, x, max_gap=3.0)
        return float(np.abs(dxdt - exact).max()), dxdt, t

    coarse, fine = worst(0.02)[0], worst(0.01)[0]
    assert coarse < 2e-3 and 3.0 < coarse / fine < 5.5      # second order: half the step, a quarter the error
    # a jump of the signal across the gap leaves every derivative alone: no difference spans it
    _, dxdt, t = worst(0.02)
    jumped = np.stack([np.sin(2 * t), np.exp(-t) * np.cos(t)], axis=1)
    jumped[len(t) // 2:] += 100.0
    np.testing.assert_allclose(data.derivatives(t, jumped)[0], dxdt, atol=1e-9)
    # a lone sample between two gaps has no derivative and is left out
    lone = np.array([0.0, 0.1, 0.2, 5.0, 10.0, 10.1, 10.2])
    assert data.derivatives(lone, lone[:, None] ** 2)[1].tolist() == [True] * 3 + [False] + [True] * 3


def test_unwrapped_angles_many_turns_away_give_the_same_data_and_fit_as_wrapped_ones(tmp_path):
    t = np.linspace(0, 12, 400)
    theta = 1.3 * t + 0.4 * np.sin(2 * t)            # a rotating arm: it wraps around every ~5 s
    omega = 1.3 + 0.8 * np.cos(2 * t)
    wrapped = (theta + math.pi) % (2 * math.pi) - math.pi
    files = [_write_csv(tmp_path / f"{name}.csv", {"t": t, "a": q, "w": omega})
             for name, q in (("wrapped", wrapped), ("encoder", theta + 2 * math.pi * 40))]
    sets = [data.get_dataset(f, q="a", v="w", periodic="a") for f in files]
    for key in ("x", "dxdt", "test_x", "test_dxdt"):
        np.testing.assert_allclose(sets[0][key], sets[1][key], atol=2e-5)
    assert np.abs(sets[0]["x"][:, 0]).max() <= math.pi
    # the angle's derivative is the angular velocity (no 2 pi jumps at the wraps), in scaled units
    tau = sets[0]["scale"]["tau"]
    np.testing.assert_allclose(sets[0]["dxdt"][:, 0] / tau, omega[:len(sets[0]["x"])], atol=3e-3)
    losses = []
    for f in files:
        config = train.Config(data=str(f), q="a", v="w", periodic="a", model="mechanical", hidden_dim=16,
                              total_steps=30, save_dir=str(tmp_path / "runs"))
        losses.append(hnn.load_run(hnn.run_experiment(config))[2]["test_loss"])
    assert losses[0] == pytest.approx(losses[1], rel=1e-3)


def test_the_scale_keeps_hamiltons_equations_with_h_over_b_squared():
    # H = p^2 / (2 m) + k q^2 / 2 with m = 2, k = 8: dq/dt = p / m, dp/dt = -k q
    rng = np.random.default_rng(0)
    q, p = rng.normal(5.0, 3.0, (50, 1)), rng.normal(0.0, 40.0, (50, 1))
    scale = data.Scale.fit(q, p, np.array([False]), "canonical")
    x = scale.x(q, p)
    dxdt = scale.dxdt(p / 2.0, -8.0 * q)
    # H'(q', p') = H(q0 + a q', b p') / b^2: its symplectic gradient (dH'/dp', -dH'/dq')
    a, b, q0 = scale.a, scale.b, scale.q0[0]
    dh_dp = b * (b * x[:, 1:]) / 2.0 / b ** 2
    dh_dq = a * 8.0 * (q0 + a * x[:, :1]) / b ** 2
    np.testing.assert_allclose(dxdt, np.concatenate([dh_dp, -dh_dq], axis=1), rtol=1e-12)
    assert abs(x[:, 0].mean()) < 1e-12 and scale.tau == pytest.approx(a / b)


# ----------------------------------------------------------------------------------------------
# the right kind


def test_a_damped_oscillator_in_a_csv_round_trips_to_the_dissipative_kind(tmp_path):
    path = _write_csv(tmp_path / "damped.csv", _damped())
    rec = data.load(path, time="time", q="x", v="v", trial="run")
    held = mm.Heldout(data, rec, 0.3, None, 3.0)
    errors, losses = {}, {}
    for kind in ("hnn", "dissipative"):
        config = train.Config(data=str(path), time="time", q="x", v="v", trial="run", model=kind, hidden_dim=32,
                              total_steps=600, learn_rate=3e-3, save_dir=str(tmp_path / "runs"))
        run = hnn.run_experiment(config)
        scale = json.loads((run / "scale.json").read_text())
        assert scale["state"] == "velocity" and scale["a"] > 0
        model = mm.Model(data, run, scale, rec.state)
        errors[kind] = mm.measure(model, held)["prediction_error"]["median"]
        losses[kind] = model.metrics["test_loss"]
    # friction is what an energy-conserving flow cannot fit: the dissipative kind wins on both
    assert losses["dissipative"] < 0.5 * losses["hnn"]
    assert errors["dissipative"] < 0.5 * errors["hnn"] < held.naive["median"]


def _double_well(path: Path, metre: float) -> Path:
    """Four trials of the double well H = v^2/2 + x^4/4 - x^2/2 (unit mass, x in metres), integrated by DOP853 at
    rtol 1e-12, with their exact derivative columns, written in units of ``metre`` (1: metres, 1000: millimetres)."""
    from scipy.integrate import solve_ivp

    cols = {"run": [], "t": [], "x": [], "v": [], "dx": [], "dv": []}
    for k, start in enumerate([(1.2, 0.0), (-0.6, 0.3), (0.4, -0.9), (-1.5, 0.2)]):
        t = np.arange(200) * 0.05
        y = solve_ivp(lambda t, y: [y[1], y[0] - y[0] ** 3], (0, t[-1]), start, t_eval=t, method="DOP853",
                      rtol=1e-12, atol=1e-12).y
        cols["run"] += [k] * len(t)
        cols["t"] += list(t)
        for name, a in zip(("x", "v", "dx", "dv"), (y[0], y[1], y[1], y[0] - y[0] ** 3)):
            cols[name] += list(metre * a)
    return _write_csv(path, cols)


def _terms(side: str) -> dict:
    """``{term: coefficient}`` of one printed side (``'0.5 - x^2 + 2.5e-07 sin(2 x - 0.1) v'``), its constant as
    ``'1'``: split at the top-level `` + `` and `` - `` (a trig argument's sign stays inside its brackets)."""
    pieces, depth, start = [], 0, 0
    for i, char in enumerate(side):
        depth += (char == "(") - (char == ")")
        if depth == 0 and side[i:i + 3] in (" + ", " - "):
            pieces.append(side[start:i])
            start = i + 1
    out = {}
    for piece in pieces + [side[start:]]:
        piece = piece.strip()
        sign = -1.0 if piece.startswith("-") else 1.0
        piece = piece.lstrip("+- ")
        number = re.match(r"[\d.]+(?:e[-+]?\d+)?(?= |$)", piece)
        term = piece[number.end():].strip() if number else piece
        out[term or "1"] = sign * (float(number.group()) if number else 1.0)
    return out


def _degree(term: str) -> int:
    """The polynomial degree of a printed term (``'x^2 v'``: 3; a sine or cosine factor counts 0)."""
    return sum(int(f.split("^")[1]) if "^" in f else 1 for f in re.sub(r"\w+\([^)]*\)", "", term).split())


def test_a_known_h_through_the_measured_path_prints_in_each_files_units(tmp_path):
    """The same double well in metres and in millimetres: the library's H and SINDy's field come back as the
    file's physics in the file's columns and units (the run fits the study's scaled, shifted coordinates)."""
    printed = {}
    for metre in (1.0, 1000.0):
        path = _double_well(tmp_path / f"well-{metre:g}.csv", metre)
        rec = data.load(path, time="t", q="x", v="v", trial="run", dxdt="dx,dv")
        rungs = [("hnn", "library")] + ([("baseline", "sindy")] if hnn.fits.sindy.version() else [])
        for kind, fit in rungs:
            config = train.Config(data=str(path), time="t", q="x", v="v", trial="run", dxdt="dx,dv", model=kind,
                                  fit=fit, save_dir=str(tmp_path / "runs"))
            run = hnn.run_experiment(config)
            model = mm.Model(data, run, json.loads((run / "scale.json").read_text()), rec.state)
            printed[metre, fit] = mm.equation(model, rec)
    # in millimetres x and v are 1000x, H = v^2/2 + x^4/4 - x^2/2 is 1e6x: H_mm = v^2/2 - x^2/2 + 2.5e-7 x^4
    truth = {1.0: {"x^2": -0.5, "v^2": 0.5, "x^4": 0.25}, 1000.0: {"x^2": -0.5, "v^2": 0.5, "x^4": 2.5e-7}}
    for metre, physics in truth.items():
        h = _terms(printed[metre, "library"].removeprefix("H = "))
        # exact derivatives: the library recovers H' to 1e-10 in its own coordinates (test_fits); undoing a
        # shift of about the scale sums at most 2^4 binomial terms of it per coefficient: 1e-8. The equation prints
        # 4 significant digits, a rounding of at most 5e-4 relative: that is the bound here
        for term, value in physics.items():
            assert h[term] == pytest.approx(value, rel=5e-4), (metre, printed[metre, "library"])
        # every other term but H's free constant is the fit's round-off: below 1e-8 of H over the data (|x| < 1.6 m)
        reach = 1.6 * metre
        scale = 0.25 * reach ** 4 / metre ** 2
        for term, value in h.items():
            if term not in physics and term != "1":
                assert abs(value) * reach ** _degree(term) <= 1e-8 * scale, (term, printed[metre, "library"])
        assert not re.search(r"\b[qp]\d?\b", printed[metre, "library"]), printed[metre, "library"]
        if (metre, "sindy") in printed:
            dx, dv = printed[metre, "sindy"].split("; ")
            assert dx == "dx/dt = v", printed[metre, "sindy"]
            field = _terms(dv.removeprefix("dv/dt = "))
            assert field["x"] == pytest.approx(1.0, rel=5e-4) and field["x^3"] == pytest.approx(-1 / metre ** 2, rel=5e-4)


def test_the_study_writes_the_card_with_the_issues_fields(tmp_path, monkeypatch):
    path = _write_csv(tmp_path / "damped.csv", _damped(trials=2, n=100))
    monkeypatch.setattr(study, "QUICK_STEPS", 40)
    monkeypatch.setattr(measured_study, "QUICK_WIDTHS", (8,))
    out = tmp_path / "card"
    scene_study.main(["--data", str(path), "--time", "time", "--q", "x", "--v", "v", "--trial", "run", "--quick",
                      "--seeds", "2", "--out", str(out), "--energy", "0.5*v**2 + 2*x**2"])
    card = json.loads((out / "scene.json").read_text())
    kinds = {row["kind"] for row in card["rows"]}
    # every model trained and measured at each seed, each its own run
    assert sorted(row["seed"] for row in card["rows"]) == sorted([0, 1] * len(kinds))
    assert len({row["run"] for row in card["rows"]}) == len(card["rows"]) and card["meta"]["seeds"] == [0, 1]
    chosen = card["chosen"]
    assert chosen["n_seeds"] == 2 and set(chosen["runs"]) <= {r["run"] for r in card["rows"]}
    mine = [r["prediction_error"]["median"] for r in card["rows"] if r["run"] in chosen["runs"]]
    assert chosen["prediction_error"]["median"] == pytest.approx(sum(mine) / 2)
    assert (chosen["prediction_error"]["min"], chosen["prediction_error"]["max"]) == (min(mine), max(mine))
    # every studied kind that reads observed [q, v] (the constrained ones need a constraint graph), and the fits'
    # rungs of them (scene_rungs: a sampled HNN, our library, SINDy where pysindy is installed)
    assert {k for k in kinds if "+" not in k} == {kind for kind, row in hnn.MODEL_KINDS.items()
                                                  if row.studied and row.reads("velocity") and row.family is None}
    assert {"hnn+swim", "hnn+library"} <= kinds <= {"hnn+swim", "hnn+library", "baseline+sindy"} | {
        k for k in kinds if "+" not in k}
    # whether anything is enough at 40 steps rests on round-off (SINDy's threshold, the seeds' errors): the card
    # names its cheapest enough model exactly when it says one is enough, on any box
    assert ("cheapest to train that is enough" in (out / "scene.md").read_text()) == chosen["enough"]
    assert {"baseline", "hnn", "separable", "dissipative", "mechanical", "second_order"} <= kinds
    for row in card["rows"]:
        assert {"kind", "hidden_dim", "train_fraction", "prediction_error", "run"} <= set(row)
        assert row["prediction_error"]["median"] <= row["prediction_error"]["mean"] * 10
        assert Path(row["run"]).is_dir() and "energy_drift" in row
        # a library's equation reads the file's columns (x, v), not the study's scaled q and p
        assert not re.search(r"\b[qp]\b", row.get("equation", "")), row["equation"]
    assert set(card["naive"]) >= {"median", "mean"} and card["chosen"]["run"] in {r["run"] for r in card["rows"]}
    means = [m["error"][0] for m in measured_study.models(card["rows"]).values()]
    assert card["chosen"]["prediction_error"]["median"] <= 2 * min(means)
    text = (out / "scene.md").read_text()
    # 40 steps do not beat the naive extrapolation here: the card says so instead of calling its pick enough
    assert ("is enough" in text) == chosen["enough"] and ("NOT enough" in text) == (not chosen["enough"])
    assert "(mean over 2 seeds)" in text and "2 seeds a model of 3" in text
    # analysis/score.py scores a run of the study as the study measured it
    row = card["rows"][0]
    scored = score.score_run(row["run"], energy="0.5*v**2 + 2*x**2")
    for key in ("prediction_error", "valid_time", "energy_drift", "test_loss"):
        assert scored[key] == row[key], key


def _seed_row(kind, width, seed, error, params):
    return {"kind": kind, "hidden_dim": width, "train_fraction": 1.0, "seed": seed, "params": params,
            "prediction_error": {"median": error, "mean": 2 * error}, "valid_time": {"median": 1.0},
            "test_loss": error, "train_seconds": 1.0, "rollout_seconds": 0.1, "run": f"{kind}-{width}-{seed}"}


def test_the_card_chooses_on_seed_means_and_says_what_the_seeds_cannot_separate():
    naive = {"median": 10.0, "mean": 10.0, "starts": 5}
    # seed 0 alone would pick the small HNN (1.0 against the best 1.0); its seeds' mean (1.0, 5.0, 6.0 -> 4.0)
    # is 4x the wide HNN's (1.0), so the means pick the separable model of middle size, whose highest seed
    # (2.5) is over 2x; the small HNN's lowest seed is within 2x: the seeds cannot separate it
    rows = [_seed_row("hnn", 8, s, e, 100) for s, e in enumerate((1.0, 5.0, 6.0))]
    rows += [_seed_row("separable", 32, s, e, 500) for s, e in enumerate((1.2, 1.4, 2.5))]
    rows += [_seed_row("baseline", 200, s, e, 5000) for s, e in enumerate((0.9, 1.0, 1.1))]
    chosen, said = measured_study._card(rows, naive, 100.0)
    assert (chosen["kind"], chosen["n_seeds"]) == ("separable", 3)
    assert chosen["prediction_error"]["median"] == pytest.approx(1.7)
    assert chosen["runs"] == ["separable-32-0", "separable-32-1", "separable-32-2"]
    assert chosen["unsettled"] == ["hnn, width 8, 1 of the data"] and chosen["pick_straddles"] is True
    text = " ".join(said)
    assert "cannot separate from it the smaller hnn (width 8, 1)" in text
    assert "highest seed (2.5) is over 2x" in text
    # the best conserving (separable, 1.2-2.5) and non-conserving (baseline, 0.9-1.1) ranges do not overlap
    assert "The energy-conserving kinds hurt: best separable" in text
    # one seed each: nothing is said to be inseparable, and the card says the seeds were not tested
    first, said = measured_study._card([r for r in rows if r["seed"] == 0], naive, 100.0)
    assert first["kind"] == "hnn" and "One seed" in " ".join(said) and "cannot" not in " ".join(said)
    assert first["unsettled"] is None and first["pick_straddles"] is None


def test_the_cards_words_come_from_its_thresholds():
    naive = {"median": 1.0, "mean": 1.0, "starts": 5}
    chosen, said = measured_study._card([_seed_row("baseline", 32, 0, 0.0043, 100)], naive, 2.0)
    assert chosen["enough"] and "0.0043x the naive extrapolation's" in said[0] and " is enough: " in said[0]
    # a 1-rad error on a double pendulum whose positions spread 1.5 rad: half the naive error, yet no prediction
    chosen, said = measured_study._card([_seed_row("hnn", 32, 0, 0.5, 100)], {**naive, "median": 2.0}, 1.5)
    assert not chosen["enough"] and "NOT enough" in said[0] and "over 0.1 of the spread" in said[0], said[0]
    assert "is enough" not in said[0]
    chosen, said = measured_study._card([_seed_row("hnn", 32, 0, 0.6, 100)], naive, 100.0)
    assert not chosen["enough"] and "not under 0.5 of the naive one" in said[0]
    guide = measured_study.guide({"x": {"chosen": {**chosen, "n_seeds": 1}, "naive": naive, "units": "units of q",
                                        "horizon": 1.0, "date": "d", "commit": "c"}})
    assert "| x | none is enough" in guide


def test_the_card_names_the_cheapest_model_enough_and_a_library_that_found_the_equations():
    naive = {"median": 10.0, "mean": 10.0, "starts": 5}
    rows = [_seed_row("hnn", 200, s, 1.0, 5000) for s in range(2)]
    rows += [{**_seed_row("hnn+library", 200, s, 1.1, 21), "train_seconds": 0.01, "equation": "H = x^2 + v^2"}
             for s in range(2)]
    rows += [{**_seed_row("baseline+sindy", 200, s, 9.0, 26), "train_seconds": 0.001} for s in range(2)]
    chosen, said = measured_study._card(rows, naive, 100.0)
    text = " ".join(said)
    assert chosen["kind"] == "hnn+library" and chosen["cheapest"]["kind"] == "hnn+library"   # SINDy: 9x the best
    assert "A library is enough here: it found the equations hnn+library `H = x^2 + v^2`" in text
    assert chosen["libraries"] == [{"kind": "hnn+library", "fraction": 1.0, "train_seconds": 0.01,
                                    "equation": "H = x^2 + v^2"}]
    _, said = measured_study._card([r for r in rows if r["kind"] != "hnn+library"], naive, 100.0)
    assert "No library (hnn+library, baseline+sindy) is enough here: the nearest, baseline+sindy 9 (9-9), is over 2x " \
        "of the best" in " ".join(said)


def test_the_cards_verdict_is_one_decision_on_rows_that_used_to_contradict():
    naive = {"median": 1.0, "mean": 1.0, "starts": 5}
    # the library is the smallest within 2x of the best (0.55 against 0.3) but not under 0.5 of the naive error; the
    # wide baseline is both. The card once called the library "NOT enough: no kind predicts this scene", then "the
    # cheapest to train that is enough" and "A library is enough here": now the pick is the smallest model enough
    rows = [_seed_row("baseline", 200, s, e, 5000) for s, e in enumerate((0.28, 0.32))]
    rows += [{**_seed_row("hnn+library", 200, s, e, 21), "train_seconds": 0.01, "equation": "H = x^2 + v^2"}
             for s, e in enumerate((0.5, 0.6))]
    decision = measured_card.decide(rows, naive, 100.0)
    assert decision.is_enough and decision.within == (("baseline", 200, 1.0), ("hnn+library", 200, 1.0))
    assert decision.enough == (("baseline", 200, 1.0),) and decision.libraries == ()
    assert decision.pick == decision.cheapest == ("baseline", 200, 1.0)
    chosen, said = measured_study._card(rows, naive, 100.0)
    text = " ".join(said)
    assert chosen["kind"] == "baseline" and chosen["enough"] and chosen["cheapest"]["kind"] == "baseline"
    assert chosen["libraries"] == [] and "NOT enough" not in text and "no kind predicts" not in text
    assert said[0].startswith("baseline, width 200, 1 of the data (5000 parameters") and " is enough: " in said[0]
    assert "No library (hnn+library, baseline+sindy) is enough here: the nearest, hnn+library 0.55 (0.5-0.6), is not " \
        "under 0.5 of the naive one" in text
    # the library's lowest seed (0.5) passes what its mean (0.55) fails: the seeds cannot separate it from the pick
    assert chosen["unsettled"] == ["hnn+library, width 200, 1 of the data"] and chosen["pick_straddles"] is False
    assert "their means are not under 0.5 of the naive one, their lowest seeds within it" in text
    # the naive extrapolation twice as good: nothing is enough, and no sentence says that anything is
    chosen, said = measured_study._card(rows, {**naive, "median": 0.5}, 100.0)
    text = " ".join(said)
    assert not chosen["enough"] and chosen["cheapest"] is None and chosen["libraries"] == []
    assert chosen["kind"] == "hnn+library" and "NOT enough" in said[0] and "is enough" not in text
    assert "No model predicts this scene well enough to name the cheapest to train, nor a library's equations." in said
    # and the tables read the same decision
    guide = measured_study.guide({"x": {"chosen": chosen, "naive": naive, "units": "units of x", "horizon": 1.0,
                                        "date": "d", "commit": "c"}})
    assert "| x | none is enough" in guide and "| none is enough | (d, commit c) |" in guide


def test_the_card_says_two_kinds_cannot_be_told_apart_when_their_seeds_overlap():
    rows = [_seed_row("hnn", 32, s, e, 100) for s, e in enumerate((1.0, 2.0, 3.0))]
    rows += [_seed_row("baseline", 32, s, e, 100) for s, e in enumerate((2.5, 3.5, 4.5))]
    _, said = measured_study._card(rows, {"median": 10.0, "mean": 10.0, "starts": 5}, 100.0)
    # 2.0 against 3.5 would read "helped"; the ranges 1-3 and 2.5-4.5 overlap
    assert "The energy-conserving kinds and the others cannot be told apart on these seeds" in " ".join(said)


def test_the_readme_guide_records_the_fewest_seeds_and_names_the_cards_below_three():
    card = {"kind": "hnn", "hidden_dim": 32, "train_fraction": 1.0, "train_seconds": 1.0,
            "prediction_error": {"median": 1.0, "min": 0.5, "max": 1.5, "mean": 2.0}}
    entry = {"naive": {"median": 3.0}, "units": "units of x", "horizon": 0.5, "date": "d", "commit": "abcdef1"}
    registry = {"a": {**entry, "chosen": {**card, "n_seeds": 3}}, "b": {**entry, "chosen": card}}
    seeds = measured_study.guide_seeds(registry)
    assert seeds.count == 1 and seeds.why.startswith("b filed from fewer seeds")
    assert measured_study.guide_seeds({"a": registry["a"]}).count == 3
    lines = measured_study.guide(registry).splitlines()
    assert "| 1 (0.5-1.5); naive 3 (units of x) | 3 |" in lines[2] and "| 1; naive 3 (units of x) | 1 |" in lines[3]
    assert "| one seed: not tested |" in lines[3]


# ----------------------------------------------------------------------------------------------
# bad input: one error line each


def _error(argv, capsys, main=None) -> str:
    with pytest.raises(SystemExit) as exit_:
        (main or (lambda a: hnn.command.run_main(train.main, a)))(argv)
    assert exit_.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize("text, flags, expect", [
    ("t,x,v\n0,1,2\n0.1,1,2\n0.2,1,2\n0.3,1,2\n0.4,1,2\n0.5,1,2\n", ["--q", "xx"], r"'xx'.*did you mean 'x'"),
    ("t,x,v\n0,1,2\n0.1,one,2\n", ["--q", "x"], r"line 3, column 'x': 'one' is not a number"),
    ("t,x,v\n0,1,2\n0.1,1,nan\n", ["--q", "x"], r"line 3, column 'v': the value is nan"),
    ("t,x,v\n0,1,2\n0.1,1,inf\n", ["--q", "x"], r"line 3, column 'v': the value is inf"),
    # a cell the arithmetic cannot hold: its square overflows float64 in the RMS the scaling takes
    ("t,x,v\n0,1,2\n0.1,1e300,2\n0.2,1,2\n", ["--q", "x"], r"line 3, column 'x': the value 1e\+300 is too large "
                                                        r"for the arithmetic"),
    ("t,x,v\n0,1,2\n0.2,1,2\n0.1,1,2\n", ["--q", "x"], r"line 4: time t=0.1 does not increase"),
    ("t,x,v\n0,1,2\n0.1,1,2\n0.2,1,2\n", ["--q", "x"], r"trial 0 .* has 3 rows: too few to split"),
    ("", ["--q", "x"], r"the file is empty"),
    ("% t x v\n", ["--q", "x"], r"no rows of numbers"),
    ("t,x,v\n0,1,2\n", ["--q", "x", "--v", "v", "--p", "v"], r"--v COLS or .* --p COLS"),
])
def test_every_bad_input_is_one_error_line(tmp_path, capsys, text, flags, expect):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    argv = ["--data", str(path), "--save_dir", str(tmp_path)] + flags + (["--v", "v"] if "--v" not in flags else [])
    assert re.search(expect, _error(argv, capsys)), expect


def test_trials_out_of_order_a_short_horizon_tail_and_wrong_kinds_are_one_error_line(tmp_path, capsys):
    path = _write_csv(tmp_path / "trials.csv", {"run": [0] * 8 + [1] * 8 + [0] * 8, "t": list(range(8)) * 3,
                                                 "x": np.arange(24.0), "v": np.ones(24)})
    assert "trial 0 starts again" in _error(["--data", str(path), "--q", "x", "--v", "v", "--trial", "run"], capsys)
    damped = _write_csv(tmp_path / "damped.csv", _damped(trials=2, n=60))
    study = ["--data", str(damped), "--time", "time", "--q", "x", "--v", "v", "--trial", "run", "--quick"]
    line = _error(study + ["--horizon", "50"], capsys, scene_study.main)
    assert "too short for --horizon 50" in line
    assert "--energy" in _error(study + ["--energy", "0.5*vv**2"], capsys, scene_study.main)
    # second_order moves q by a velocity: refused on canonical momenta
    line = _error(["--data", str(damped), "--time", "time", "--q", "x", "--p", "v", "--trial", "run",
                   "--model", "second_order", "--total_steps", "1", "--save_dir", str(tmp_path)], capsys)
    assert "cannot be fit to states in 'canonical' coordinates" in line
    line = _error(["--data", str(damped), "--time", "time", "--q", "x,v", "--p", "v,x", "--periodic", "x",
                   "--model", "mechanical", "--save_dir", str(tmp_path)], capsys)
    assert "all or none" in line


def test_an_npz_of_columns_reads_like_its_csv(tmp_path):
    cols = _damped(trials=2, n=40)
    np.savez(tmp_path / "d.npz", **{k: np.asarray(v) for k, v in cols.items()})
    a = data.get_dataset(tmp_path / "d.npz", time="time", q="x", v="v", trial="run")
    b = data.get_dataset(_write_csv(tmp_path / "d.csv", cols), time="time", q="x", v="v", trial="run")
    for key in ("x", "dxdt", "test_x", "test_dxdt"):
        np.testing.assert_array_equal(a[key], b[key])


# ----------------------------------------------------------------------------------------------
# docs/measured.md, verbatim


def _docs_commands() -> list[str]:
    text = (REPO / "docs" / "measured.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)```", text, flags=re.S)
    return [line for block in blocks for line in block.splitlines() if line.startswith("python ")]


def _run_doc_command(command: str, tmp_path: Path) -> subprocess.CompletedProcess:
    argv = [sys.executable] + [arg.replace("results-quick/", f"{tmp_path}/") for arg in shlex.split(command)[1:]]
    return subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**__import__("os").environ, "OMP_NUM_THREADS": "1"})


def test_the_docs_train_command_runs_verbatim(tmp_path):
    commands = _docs_commands()
    assert len(commands) == 2 and "train.py" in commands[0] and "--quick" in commands[1]
    done = _run_doc_command(commands[0], tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    run = Path(done.stdout.strip().splitlines()[-1].removeprefix("saved the run to ").split(" (created ")[0])
    assert (run / "scale.json").is_file() and run.parent == tmp_path / "measured-runs"


@pytest.mark.slow
def test_the_docs_scene_study_command_runs_verbatim(tmp_path):
    done = _run_doc_command(_docs_commands()[1], tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    card = json.loads((tmp_path / "double-linear" / "scene.json").read_text())
    assert card["chosen"] and len(card["rows"]) == 6


def test_trajectory_snippets_are_consecutive_even_steps_inside_one_part(tmp_path):
    t = np.arange(60) * 0.1
    t[25:] += 0.03                    # one step 30% long: no snippet may span it
    path = _write_csv(tmp_path / "even.csv", {"t": t, "x": t, "v": np.ones(60)})     # x = t names its row
    d = data.get_dataset(path, q="x", v="v", snippet_steps=4)
    a, q0 = d["scale"]["a"], d["scale"]["q0"][0]
    found = []
    for part in ("snippets", "test_snippets"):
        x = d[part].reshape(len(d[part]), 5, 2)[:, :, 0] * a + q0
        rows = [int(np.argmin(np.abs(t - snip[0]))) for snip in x]
        for snip, row in zip(x, rows):
            np.testing.assert_allclose(snip, t[row:row + 5], atol=1e-5)      # five consecutive samples
        found.append(rows)
    # train rows 0-41 cut at the long step (0-24, 25-41), held-out rows 42-59; non-overlapping
    assert found == [[0, 5, 10, 15, 20, 25, 30, 35], [42, 47, 52]]
    config = train.Config(data=str(path), q="x", v="v", model="mechanical", objective="trajectory", hidden_dim=8,
                          total_steps=5, save_dir=str(tmp_path))
    assert math.isfinite(hnn.load_run(hnn.run_experiment(config))[2]["test_loss"])


def test_the_velocity_mismatch_measures_how_far_v_is_from_dq_dt(tmp_path):
    cols = _damped(trials=2, n=200)
    fields = dict(time="time", q="x", v="v", p="", trial="run", periodic="", dxdt="", test_fraction=0.3, max_gap=3.0)
    exact = measured_study.velocity_mismatch({**fields, "data": str(_write_csv(tmp_path / "a.csv", cols))})
    cols["v"] = list(1.2 * np.asarray(cols["v"]))       # velocities 20% too large: dq/dt - v = -v / 6
    off = measured_study.velocity_mismatch({**fields, "data": str(_write_csv(tmp_path / "b.csv", cols))})
    assert exact[0] < 5e-3 and off[0] == pytest.approx(1 / 6, abs=5e-3)
