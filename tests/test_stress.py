"""The stress study (analysis/stress.py): its unit changes keep Hamilton's equations, a tiny grid gives
every cell one of the three outcomes, and each failure mode it meets stops with one clear error."""
import json
import warnings

import pytest
import torch

import hnn
from hnn_analysis import stress
from hnn_analysis.extremes import stress_grid as grid
from hnn_analysis.extremes.stress_report import text as stress_text

TINY = {"steps": 5, "hidden": 8, "rows": 32, "learn_rate": 1e-3}


@pytest.mark.parametrize("cell", [c for c in grid.CELLS if c != "float64"])
def test_each_unit_change_keeps_hamiltons_equations(cell):
    """In units where q, p, t read cq, cp, ct times theirs, the spring's data are Hamilton's equations of
    H' = H cq cp / ct (dq'/dt' = (cq / ct) dH/dp = (cq cp / ct) dH/dp'), checked by autograd."""
    cq, cp, ct, _, ratio = grid.CELLS[cell]
    data = grid._in_units(grid._spring(64, 0, ratio), cq, cp, ct)
    x = data["x"].clone().requires_grad_(True)
    q, p = x[:, 0] / cq, x[:, 1] / cp
    H = (0.5 * p ** 2 / ratio + 0.5 * q ** 2) * cq * cp / ct
    dH = torch.autograd.grad(H.sum(), x)[0]
    torch.testing.assert_close(data["dxdt"], torch.stack([dH[:, 1], -dH[:, 0]], 1), rtol=1e-12, atol=0)
    # and the velocity twin is d/dt of [q', dq'/dt']
    torch.testing.assert_close(data["dzdt"][:, 0], data["z"][:, 1], rtol=1e-12, atol=0)


def test_the_field_error_is_the_same_in_any_units():
    true = torch.randn(50, 4, dtype=torch.float64)
    pred = true + 0.1 * torch.randn(50, 4, dtype=torch.float64)
    units = torch.tensor([1e-3, 1e3, 1.0, 1e3], dtype=torch.float64)
    assert grid.field_error(pred * units, true * units) == pytest.approx(grid.field_error(pred, true), rel=1e-12)


def test_a_tiny_grid_gives_every_cell_one_outcome(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(grid, "QUICK", TINY)
    monkeypatch.setattr(grid, "QUICK_HORIZON", 50)
    results = grid.run(quick=True)
    meta = {"command": "python analysis/stress.py --quick", "commit": "0000000", "seconds": 1, "cpu_seconds": 1,
            "load": 0.0, "cores": 2, "cpu": "AVX2"}
    text = stress_text(results, meta)
    grid_text = text.split("**heavy mass**")[0]
    cells = [line.split(" | ")[1:] for line in grid_text.splitlines()
             if line.startswith("| ") and "nominal" not in line and "---" not in line and "cell" not in line]
    assert cells and all(c.strip(" |").split(" ")[0] in ("works", "degrades", "stops:") for row in cells for c in row)
    assert {r["kind"] for r in results["rows"]} == {"hnn", "mechanical"}
    assert "**heavy mass**" in text and {r["units"] for r in results["heavy"]} == {"auto", "off"}
    # --report rewrites the same tables from the saved JSON
    saved = tmp_path / "stress.json"
    saved.write_text(json.dumps({**results, "meta": meta}))
    stress.main(["--report", str(saved)])
    assert capsys.readouterr().out.strip().endswith(text.strip().splitlines()[-1])


def test_a_training_whose_loss_overflows_is_a_cell_that_stops_naming_the_fix(monkeypatch):
    """q and p in units 10^20 times the spring's, trained in those units (--units off): float32 squares of the
    errors overflow, the loss is no longer finite at step 0, and the cell stops with the training's error (its
    fixes named: a lower rate, clipping, float64), warned about the data's scale before."""
    monkeypatch.setitem(grid.CELLS, "x1e20", (1e20, 1e20, 1, False, 1))
    monkeypatch.setitem(grid.UNITS_OFF, "x1e20, --units off", "x1e20")
    _, row = grid.fit("hnn", "spring", "x1e20, --units off", {**TINY, "learn_rate": 1e-3})
    outcome = grid.outcome(row, {"error": 0.1})
    assert outcome.startswith("stops: DivergenceError: the training loss is") and "float64" in outcome
    assert "warned: x, dxdt off unit scale" in outcome


class _TrueSpring(torch.nn.Module):
    """The spring's exact field dx/dt = (p, -q) as a model (a parameter only for the rollout's dtype)."""

    def __init__(self):
        super().__init__()
        self.unused = torch.nn.Parameter(torch.zeros((), dtype=torch.float64))

    def time_derivative(self, x, t=None):
        return torch.stack([x[:, 1], -x[:, 0]], 1)


def test_a_rollout_past_rk4s_stability_limit_stops_naming_the_divergence():
    """RK4 on the exact spring at omega dt = 3.0, past its limit of 2.83: each step multiplies the state
    by |R(3i)| = 1.5, the rollout passes max_norm within 100 steps and raises, naming the rows, instead
    of returning a path that cannot be trusted. At 2.5, inside the limit, it runs (and loses energy)."""
    row = grid.energy_change(_TrueSpring(), "hnn", 100, 3.0)
    assert row["stop"].startswith("DivergenceError: rk4") and "Reduce the step size" in row["stop"]
    assert 0.5 < grid.energy_change(_TrueSpring(), "hnn", 100, 2.5)["error"] <= 1.0
    assert grid.energy_change(_TrueSpring(), "hnn", 100, 0.1)["error"] < 1e-4


def test_a_mechanical_fit_whose_m_inverse_lies_under_its_floor_warns_naming_the_fix():
    """q in 10^-3 units (p in 10^3): the spring's M^-1 becomes 10^-6, under MechanicalHNN's floor eps = 1e-4,
    where the grid measured an error of 300 (docs/stress.md). The derivative objective now says so before
    training; at the scene's own units it says nothing."""
    model = hnn.kinds.model_from_args({"kind": "mechanical", "input_dim": 2, "hidden_dim": 8})
    for cell, warns in (("q x1e-3", True), ("nominal", False)):
        data = grid._in_units(grid._spring(64, 0, 1.0), *grid.CELLS[cell][:3])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            hnn.DerivativeObjective().train_options(model, hnn.specs.ObjectiveSpec(),
                                                    {"x": data["x"], "dxdt": data["dxdt"]})
        floor = [w for w in caught if "eigenvalue floor" in str(w.message)]
        assert bool(floor) == warns, cell
        assert not warns or "Scale your states" in str(floor[0].message)


@pytest.mark.parametrize("kind", ["hnn", "mechanical", "second_order", "constrained", "lagrangian"])
def test_at_the_defaults_every_unit_cell_is_one_fit(kind):
    """At hnn.train's defaults (the model in Rescaled, --units auto) each change of units by 10^-3 or 10^3 is
    rescaled to the same canonical numbers, so every such cell gives one field error. Tolerance 1e-4 relative:
    the unit conversions' float32 rounding, carried through the fit (measured up to 3e-7 on the spring's runs,
    tests/test_units.py), far below a seed's spread. The nominal, which auto leaves in its own units (sizes
    0.45 to 0.9), is another fit: not compared."""
    # a kind of [q, qdot] does not read p: its p cells are its nominal's data
    moved = ("q ", "t ") if kind in grid.VELOCITY else ("q ", "p ", "t ")
    rows = [grid.fit(kind, "spring", cell, TINY)[1] for cell in grid.CELLS if cell.startswith(moved)]
    for row in rows:
        assert row["error"] == pytest.approx(rows[0]["error"], rel=1e-4), row["cell"]
        assert not row["warned"] and "scales" in row


def test_the_two_masses_are_rescaled_per_pair_and_their_one_scale_cell_is_not():
    """Masses 1 and 1000: the heavy cell's momenta spread 30x, so auto rescales each pair on its own (one product
    s_q_i s_p_i), while the 'one scale' cell is rescaled with one scale for all q and one for all p."""
    per_pair = grid.fit("hnn", "masses", "mass ratio 1e3", TINY)[1]
    one = grid.fit("hnn", "masses", grid.ONE_SCALE, TINY)[1]
    assert isinstance(per_pair["scales"]["q"], list) and isinstance(one["scales"]["q"], float)
    assert "rescaled per pair" in grid.outcome(per_pair, {"error": 1.0})
    assert grid.applies("constrained", "masses") and not grid.applies("constrained", "arm")


def test_the_heavy_mass_rows_measure_every_kind_and_units():
    rows = grid.heavy({**TINY, "rows": 64}, 0)
    assert {(r["kind"], r["units"]) for r in rows} == {(k, u) for k in ("mechanical", "hnn") for u in ("auto", "off")}
    assert all("field_error" in r and ("rollout_error" in r or "rollout_stop" in r) for r in rows)
    assert all("inverse_mass_error" in r for r in rows if r["kind"] == "mechanical")


def test_a_rollout_past_rk4s_limit_is_a_cell_marked_warned():
    """The exact spring at omega dt = 3.0 past RK4's limit (2.83): hnn.rollout warns before it starts, and the
    cell says so beside its outcome; at 0.1 no mark."""
    past = grid.energy_change(_TrueSpring(), "exact", 100, 3.0)
    assert past["warned"] == ["dt past RK4's stability limit"]
    assert "(warned: dt past RK4's stability limit)" in grid.outcome(past, {"error": 1e-6})
    assert "warned" not in grid.energy_change(_TrueSpring(), "exact", 100, 0.1)
