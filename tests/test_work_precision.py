"""The work-precision study (analysis/integrator_study/work_precision.py): the peers' solvers wired to the
same field agree with an exact solution to their tolerance, the equal-error interpolation is exact on a
synthetic curve, and the --quick path produces the rows, tables and plot."""
import json
import math
import statistics

import numpy as np
import pytest
import torch

import hnn
from hnn_analysis.integrator_study import peer_solvers, work_precision, work_precision_measure
from hnn_analysis.integrator_study.work_precision_report import LEVELS, at_error, comparisons, pareto_front, summary_table

OMEGA = 2.0


def oscillator(x):
    """dq/dt = p, dp/dt = -omega^2 q, a (batch, 2) field."""
    return torch.stack([x[:, 1], -OMEGA ** 2 * x[:, 0]], 1)


def exact(x0: torch.Tensor, t: np.ndarray) -> torch.Tensor:
    c, s = np.cos(OMEGA * t), np.sin(OMEGA * t)
    q0, p0 = x0[:, :1].numpy(), x0[:, 1:].numpy()
    return torch.from_numpy(np.stack([q0 * c + p0 / OMEGA * s, p0 * c - q0 * OMEGA * s], -1))


def _solver(name):
    peer = peer_solvers.PEERS[name]
    if peer.package == "torchdiffeq":
        pytest.importorskip("torchdiffeq")
    return peer


# torchdiffeq's dopri8 fills its output times from a quartic through each step's midpoint: between
# long 8th-order steps that interpolant, not the tolerance, sets the error at the output times
INTERPOLATED = {"torchdiffeq dopri8"}


@pytest.mark.parametrize("name", sorted(set(peer_solvers.PEERS) - INTERPOLATED))
@pytest.mark.parametrize("rtol", [1e-5, 1e-9])
def test_each_peer_follows_the_exact_oscillator_to_its_tolerance(name, rtol):
    peer = _solver(name)
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.8], [0.0, 0.05]], dtype=torch.float64)
    t = np.linspace(0.0, 10.0, 41)                  # about 3 periods
    stats = {}
    traj = peer.run(oscillator, x0, t, rtol=rtol, atol=rtol, stats=stats)
    assert traj.shape == (3, len(t), 2) and torch.equal(traj[:, 0], x0)
    error = float((traj - exact(x0, t)).abs().max())
    # the global error of an adaptive solver is its local tolerance summed over the steps of about
    # three periods: within 100x rtol here (measured: 8-35x)
    assert error < 100 * rtol, (name, error)
    assert error > 1e-3 * rtol          # it did not step at the reference's precision: the tolerance reached it
    assert stats["nfev"] > 10


def test_torchdiffeqs_dopri8_is_as_accurate_as_its_tolerance_on_its_steps_not_between_them():
    torchdiffeq = pytest.importorskip("torchdiffeq")
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.8], [0.0, 0.05]], dtype=torch.float64)
    t = np.linspace(0.0, 10.0, 41)
    rtol = 1e-9
    traj = peer_solvers.PEERS["torchdiffeq dopri8"].run(oscillator, x0, t, rtol=rtol, atol=rtol)
    assert traj.shape == (3, len(t), 2)
    assert float((traj - exact(x0, t)).abs().max()) > 1000 * rtol          # measured: 5500x
    on_steps = torchdiffeq.odeint(lambda s, x: oscillator(x), x0, torch.as_tensor(t), method="dopri8", rtol=rtol,
                                  atol=rtol, options={"step_t": torch.as_tensor(t)}).transpose(0, 1)
    assert float((on_steps - exact(x0, t)).abs().max()) < 100 * rtol      # stepping onto each time: 2.3x


@pytest.mark.parametrize("rtol", [1e-5, 1e-9])
def test_the_study_runs_ours_and_the_peers_on_the_same_field_and_both_agree(rtol):
    model = hnn.build_model(2, 16).double().eval()       # a learned-field stand-in: its field, frozen
    x0 = torch.tensor([[0.5, 0.1], [-0.2, 0.4]], dtype=torch.float64)
    t = np.linspace(0.0, 3.0, 11)
    reference = hnn.rollout(model, x0, t, scipy_method="DOP853", rtol=1e-13, atol=1e-13)
    runners = work_precision_measure.solvers()
    assert {"hnn dopri5", "hnn dop853", "scipy RK45", "scipy DOP853"} <= set(runners)
    counted = work_precision_measure.Counted(model.field)
    for name, run in runners.items():
        counted.reset()
        traj = run(counted, x0, t, rtol, rtol)
        assert traj.shape == (2, len(t), 2)
        # torchdiffeq's dopri8 between its steps: its quartic interpolant's error (the test above)
        bound = 1e4 * rtol if name in INTERPOLATED else 100 * rtol
        assert float((traj - reference).abs().max()) < bound, name
        assert counted.calls > 5 and counted.rows >= counted.calls and 0 < counted.seconds


def test_a_peer_takes_a_model_as_hnn_rollout_does():
    model = hnn.build_model(2, 16).double().eval()
    x0 = torch.tensor([[0.5, 0.1]], dtype=torch.float64)
    t = np.linspace(0.0, 1.0, 5)
    by_model = peer_solvers.PEERS["scipy DOP853"].run(model, x0, t, rtol=1e-10, atol=1e-10)
    by_field = peer_solvers.PEERS["scipy DOP853"].run(model.field, x0, t, rtol=1e-10, atol=1e-10)
    assert torch.equal(by_model, by_field)


def test_the_equal_error_interpolation_is_exact_on_a_power_law():
    # a work-precision curve seconds = 2e-3 * error^(-1/5) (a 5th-order method's), with one setting that
    # another beats on both counts: it is no part of the front, and the log-log interpolation is exact
    errors = [1e-2, 1e-4, 1e-6, 1e-8]
    points = [(e, 2e-3 * e ** -0.2) for e in errors] + [(1e-5, 1.0)]
    front = pareto_front(points)
    assert [p[0] for p in front] == sorted(errors)
    for error in (3e-3, 1e-5, 5e-8):
        assert at_error(front, error) == pytest.approx(2e-3 * error ** -0.2, rel=1e-12)
    assert at_error(front, 1e-4) == pytest.approx(2e-3 * 1e-4 ** -0.2)
    assert at_error(front, 1e-9) is None and at_error(front, 0.1) is None       # never extrapolated


def test_the_best_of_ours_is_the_fastest_of_ours_at_each_level():
    rows = []
    # ours: dopri5 1.5x and dop853 0.5x scipy's seconds at every level: the best of ours is dop853, 2x faster
    for solver, scale in (("hnn dopri5", 1.5), ("hnn dop853", 0.5), ("scipy RK45", 1.0)):
        for error in (1e-3, 1e-9):
            rows.append({"task": "spring", "model": "hnn", "batch": 64, "solver": solver, "status": "ok",
                         "error": error, "seconds": scale * error ** -0.2, "field_s": 0.1, "calls": 10, "rows": 640})
    lines = summary_table({"rows": rows})
    best = [line for line in lines if "best of ours" in line]
    n = sum(1e-9 <= lv <= 1e-3 for lv in LEVELS)            # the half decades both curves reach
    assert len(best) == 1 and f"2.00x ({n}/{n} level or faster)" in best[0]
    assert any(f"| dopri5 | 0.67x (0/{n}) |" in line for line in lines)


def test_comparisons_give_the_ratio_at_every_shared_level():
    rows = []
    for solver, scale, errors in (("hnn dopri5", 1.0, (1e-3, 1e-9)), ("scipy RK45", 3.0, (1e-5, 1e-11))):
        for error in errors:
            rows.append({"task": "spring", "model": "hnn", "batch": 64, "solver": solver, "status": "ok",
                         "error": error, "seconds": scale * error ** -0.2, "field_s": 0.5 * error ** -0.2,
                         "calls": 100 * error ** -0.2, "rows": 6400 * error ** -0.2})
    found = comparisons(rows)
    levels = [c["level"] for c in found]
    assert levels == [lv for lv in LEVELS if 1e-9 <= lv <= 1e-5]            # only where both curves reach
    assert all(c["ratio"] == pytest.approx(3.0) and c["bound"] == pytest.approx(6.0) for c in found)
    assert all(math.isclose(c["peer_calls"], c["ours_calls"]) for c in found)


def test_the_ratio_pairs_the_solvers_round_by_round():
    """Three rounds: quiet, loaded, then the load on ours alone. Each solver's median seconds put ours at 0.55x
    the peer's speed; round by round the peer took 1.1x ours twice, so the paired median says 1.1x, and the best
    of ours takes the fastest of ours within each round before the median."""
    rows = []
    per_round = {"hnn dopri5": (1.0, 2.0, 2.0), "hnn dop853": (1.5, 3.0, 1.2), "scipy RK45": (1.1, 2.2, 1.05)}
    for solver, seconds in per_round.items():
        for error in (1e-3, 1e-9):
            scale = error ** -0.2
            rows.append({"task": "spring", "model": "hnn", "batch": 64, "solver": solver, "status": "ok",
                         "error": error, "round_seconds": [t * scale for t in seconds],
                         "seconds": statistics.median(seconds) * scale, "field_s": 0.5 * scale, "calls": 100 * scale,
                         "rows": 6400 * scale})
    found = [c for c in comparisons(rows) if c["ours"] == "hnn dopri5"]
    assert found and all(c["peer_s"] / c["ours_s"] == pytest.approx(0.55) for c in found)
    assert all(c["ratio"] == pytest.approx(1.1) and len(c["round_ratios"]) == 3 for c in found)
    lines = summary_table({"rows": rows})
    best = next(line for line in lines if "best of ours" in line)
    # per round the best of ours: 1.1 / 1.0, 2.2 / 2.0, 1.05 / 1.2 -> 1.1, 1.1, 0.875: median 1.1
    n = sum(1e-9 <= lv <= 1e-3 for lv in LEVELS)
    assert f"1.10x ({n}/{n} level or faster)" in best
    for row in rows:                                # saved without the rounds: the medians' ratio, as before
        del row["round_seconds"]
    assert all(c["ratio"] == pytest.approx(0.55) for c in comparisons(rows) if c["ours"] == "hnn dopri5")


def test_the_best_of_ours_says_which_slower_levels_the_rounds_cannot_separate():
    """Three rounds at two error curves: ours behind scipy at the median (0.95x) but ahead in one round, so that
    level is one the rounds cannot separate; at 0.9x in every round it is slower, and no bracket says otherwise."""
    def rows_for(peer_rounds):
        rows = []
        for solver, seconds in (("hnn dopri5", (1.0, 1.0, 1.0)), ("scipy RK45", peer_rounds)):
            for error in (1e-3, 1e-9):
                scale = error ** -0.2
                rows.append({"task": "spring", "model": "hnn", "batch": 64, "solver": solver, "status": "ok",
                             "error": error, "round_seconds": [t * scale for t in seconds],
                             "seconds": statistics.median(seconds) * scale, "field_s": 0.5 * scale,
                             "calls": 100 * scale, "rows": 6400 * scale})
        return next(line for line in summary_table({"rows": rows}) if "best of ours" in line)

    n = sum(1e-9 <= lv <= 1e-3 for lv in LEVELS)
    assert f"0.95x (0/{n} level or faster; {n} the rounds cannot separate)" in rows_for((0.95, 1.05, 0.9))
    assert f"0.90x (0/{n} level or faster)" in rows_for((0.9, 0.9, 0.9))


def _untrained_spring_hnn(runs):
    config = hnn.tasks.task_config("spring", {"model": "hnn", "seed": 0, "save_dir": str(runs)})
    saved = {**config.to_dict(), "kind": config.kind, "dataset_cache_key": None}
    torch.manual_seed(0)
    model = hnn.runs.model_from_args(saved)
    with torch.no_grad():           # weights grown 3x: a field with some bends, so the tolerances show in the errors
        for weight in model.parameters():
            weight.mul_(3.0)
    metrics = {"train_loss": 0.1, "train_loss_se": 0.0, "test_loss": 0.1, "test_loss_se": 0.0, "train_seconds": 0.0}
    hnn.runs.save_run(hnn.runs.run_dir(config), model, saved, metrics)


def test_the_quick_path_writes_the_work_precision_rows(tmp_path, monkeypatch):
    monkeypatch.setattr(work_precision, "QUICK_RTOLS", (1e-4, 1e-7))
    _untrained_spring_hnn(tmp_path / "runs")
    results = work_precision.main(["--quick", "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "out")])
    rows = results["rows"]
    assert {(r["solver"], r["batch"], r["rtol"]) for r in rows} == \
        {(s, b, rtol) for b in work_precision_measure.BATCHES for s in work_precision_measure.solvers()
         for rtol in (1e-4, 1e-7)}
    for batch in work_precision_measure.BATCHES:      # scipy's step rule on one state too: a row of its own
        assert {"hnn dopri5 shared", "hnn dop853 shared"} <= {r["solver"] for r in rows if r["batch"] == batch}
    for r in rows:
        assert r["status"] == "ok" and r["error"] > 0 and 0 < r["field_s"] < r["seconds"] and r["call_us"] > 0
        assert r["rows"] == r["calls"] * r["batch"] or r["solver"].startswith("hnn")   # ours drop finished rows
    saved = json.loads((tmp_path / "out" / "work_precision.json").read_text())
    assert saved["meta"]["peers"]["scipy"] and len(saved["rows"]) == len(rows)
    text = (tmp_path / "out" / "work_precision.md").read_text()
    assert "Seconds at equal error" in text and "| spring | hnn | 64 | dop853 |" in text
    assert "| spring | hnn | 64 | dopri5 shared |" in text and "| spring | hnn | 64 | **best of ours** |" in text
    assert "seconds at each error level" in text and "every error level and pair" in text
    assert (tmp_path / "out" / "work-precision-spring.png").stat().st_size > 10_000
    assert (tmp_path / "out" / "work-precision.png").stat().st_size > 10_000


def test_a_solver_that_diverges_is_a_row_that_says_so_not_a_crash():
    def blow_up(x):                     # dx/dt = x^2 from x = 1: infinite at t = 1
        return x * x
    x0 = torch.ones(2, 2, dtype=torch.float64)
    t = np.linspace(0.0, 0.5, 5)
    runners = {"fine": lambda f, x0, t, rtol, atol: hnn.rollout(f, x0, t, method="dopri5", rtol=rtol, atol=atol),
               "diverges": lambda f, x0, t, rtol, atol: hnn.rollout(f, x0, t * 4, method="dopri5", rtol=rtol,
                                                                     atol=atol)}
    rows = work_precision_measure.measure(blow_up, x0, t, (1e-4, 1e-6), repeats=2, runners=runners)
    status = {(r["solver"], r["rtol"]): r["status"] for r in rows}
    assert status[("fine", 1e-4)] == "ok" and status[("diverges", 1e-6)].startswith("DivergenceError")
    assert all(r["error"] < 1e-3 for r in rows if r["solver"] == "fine")


def test_update_docs_without_the_saved_runs_leaves_the_page_and_says_where_to_find_them(tmp_path, monkeypatch,
                                                                                         capsys):
    (tmp_path / "docs").mkdir()
    (tmp_path / "experiment-spring").symlink_to(hnn.tasks.repo_root() / "experiment-spring")
    page = tmp_path / "docs" / "integrators.md"
    page.write_text("<!-- work-precision:begin -->\nthe last full ladder\n<!-- work-precision:end -->\n")
    monkeypatch.setenv("HNN_REPO", str(tmp_path))
    with pytest.raises(SystemExit):
        work_precision.main(["--tasks", "spring", "--repeats", "1", "--runs", str(tmp_path / "empty"),
                             "--out", str(tmp_path / "out"), "--update-docs"])
    assert "the last full ladder" in page.read_text()
    err = capsys.readouterr().err
    assert "no saved run of spring hnn, spring baseline" in err and "--runs" in err
    assert (tmp_path / "out" / "work_precision.json").exists()
