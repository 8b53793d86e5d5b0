"""The balanced loss (``--balance``, hnn/balance.py): its weights, its independence of units, its config."""
import json

import numpy as np
import pytest
import torch

import hnn
from hnn.balance import AUTO_RATIO, balance_weights, component_rms, scale_ratio, weighted

arm_data = hnn.load_task("arm")


def _columns(scales, rows=500, seed=0):
    return np.random.default_rng(seed).normal(size=(rows, len(scales))) * np.asarray(scales)


def test_weights_give_every_component_one_share():
    y = _columns([1e-3, 1.0, 1e3])
    w = balance_weights(y, "rms", "l2")
    # a zero prediction's error in each component, weighed, is 1: no component's unit decides
    np.testing.assert_allclose(w * component_rms(y) ** 2, 1.0, rtol=1e-12)
    np.testing.assert_allclose(balance_weights(y, "rms", "l1") * component_rms(y), 1.0, rtol=1e-12)
    assert scale_ratio(y) == pytest.approx(component_rms(y).max() / component_rms(y).min())


def test_auto_balances_only_components_of_different_sizes():
    assert balance_weights(_columns([1.0, 2.0]), "auto") is None           # the paper's tasks: ratios 1-3.6
    assert balance_weights(_columns([1.0, 3 * AUTO_RATIO]), "auto") is not None
    assert balance_weights(_columns([1.0, 3 * AUTO_RATIO]), "off") is None
    assert balance_weights(_columns([1.0, 2.0]), "rms") is not None
    with pytest.raises(ValueError, match="choose one of"):
        balance_weights(_columns([1.0, 2.0]), "unit")
    with pytest.raises(ValueError, match="no size"):
        balance_weights(np.c_[_columns([1.0]), np.zeros(500)], "rms")


def test_balanced_loss_is_the_same_number_in_any_units():
    """Changing the unit of each component by 10^-3..10^3 (targets and predictions alike) leaves the
    balanced loss's value unchanged; the plain loss changes by orders of magnitude."""
    y, pred = (torch.tensor(_columns([0.5, 2.0, 30.0, 7.0], seed=s)) for s in (0, 1))
    units = torch.tensor([1e-3, 1e3, 1.0, 1e3], dtype=torch.float64)

    def loss(targets, prediction, balance):
        per_element = hnn.training.l2_loss(lambda xb: prediction)
        w = balance_weights(targets, balance)
        return (weighted(per_element, w) if w is not None else per_element)(None, targets).mean().item()
    assert loss(y * units, pred * units, "rms") == pytest.approx(loss(y, pred, "rms"), rel=1e-12)
    assert loss(y * units, pred * units, "off") / loss(y, pred, "off") > 100


def _arm_fit(units: torch.Tensor, balance: str, steps: int = 60) -> torch.Tensor:
    """The weights of an HNN fit to the heavy arm's dx/dt (10 kg links: dp/dt 60x dq/dt), in the
    user's units ``units`` (q_1, q_2, p_1, p_2 scaled by them, t unchanged). The network reads the
    states in the task's units (``x / units``) and its field is converted back (``units * f``): the
    user's scene in other units, seen by the same network."""
    ds = arm_data.get_dataset(seed=0, n_train=256, n_test=8, arm=arm_data.Arm((10.0, 10.0)))
    x, dxdt = (torch.tensor(ds[k], dtype=torch.float64) * units for k in ("x", "dxdt"))
    torch.manual_seed(0)
    model = hnn.build_model(4, 32).double()
    hnn.train(model, x, dxdt, total_steps=steps, progress=False, weight_decay=1e-4,
              predict=lambda xb: units * model.time_derivative(xb / units), balance=balance)
    return torch.cat([p.detach().flatten() for p in model.parameters()])


@pytest.mark.filterwarnings("ignore:x and dxdt are far from unit scale")
def test_a_change_of_units_by_1e3_gives_the_same_fit():
    """Momenta in g m^2/s instead of kg m^2/s (10^3) or positions in mrad (10^3, with p in 10^-3 of
    its unit: the change stays canonical): the balanced fit is the same network. Tolerance 1e-8
    relative: the losses agree to float64 rounding (powers of ten are inexact in binary) and 60
    Adam steps carry that rounding, nothing more. The plain loss, in the same units, learns another
    network (its components' weights moved by 10^6)."""
    base = _arm_fit(torch.ones(4, dtype=torch.float64), "rms")
    for units in ([1.0, 1.0, 1e3, 1e3], [1e3, 1e3, 1e-3, 1e-3]):
        moved = _arm_fit(torch.tensor(units, dtype=torch.float64), "rms")
        torch.testing.assert_close(moved, base, rtol=1e-8, atol=1e-10)
    plain = _arm_fit(torch.ones(4, dtype=torch.float64), "off")
    plain_moved = _arm_fit(torch.tensor([1.0, 1.0, 1e3, 1e3], dtype=torch.float64), "off")
    assert (plain_moved - plain).abs().max() > 1e-3


def _arm_config(tmp_path, **fields):
    return hnn.tasks.task_config("arm", {"hidden_dim": 8, "total_steps": 1, "n_train": 64, "n_test": 16,
                                         "save_dir": str(tmp_path), **fields})


def test_balance_at_its_default_keeps_the_run_identity(tmp_path):
    """Runs saved before --balance existed keep their folders: 'auto' is left out of the identity;
    the other values enter it and name other folders."""
    default = _arm_config(tmp_path)
    assert "balance" not in default.identity()
    keys = {_arm_config(tmp_path, balance=b).key() for b in ("off", "rms")}
    assert len(keys | {default.key()}) == 3


@pytest.mark.filterwarnings("ignore:x and dxdt are far from unit scale")
def test_a_run_records_what_auto_resolved_to(tmp_path):
    """In the arm's own units (--units off) the 10 kg arm's dp/dt is 60x its dq/dt: --balance auto weighs each
    component by its RMS, recorded; at 1 kg (ratio 6.4) the plain loss. At the default --units auto the 10 kg
    arm's p (RMS 24) is rescaled first, recorded too."""
    heavy = hnn.run_experiment(_arm_config(tmp_path, model="mechanical", mass=10.0, units="off"))
    saved = json.loads((heavy / "args.json").read_text())
    assert saved["balance"] == "auto"
    np.testing.assert_allclose(np.asarray(saved["loss_weights"]) * component_rms(
        _arm_config(tmp_path, mass=10.0).dataset()["dxdt"]) ** 2, 1.0, rtol=1e-6)
    light = hnn.run_experiment(_arm_config(tmp_path, model="mechanical"))     # 1 kg: ratio 6.4, the plain loss
    assert not {"loss_weights", "unit_scales"} & set(json.loads((light / "args.json").read_text()))
    rescaled = hnn.run_experiment(_arm_config(tmp_path, model="mechanical", mass=10.0))
    assert set(json.loads((rescaled / "args.json").read_text())["unit_scales"]) == {"q", "p", "t"}


def test_balance_refuses_an_objective_with_its_own_loss(tmp_path):
    with pytest.raises(ValueError, match="drop balance"):
        _arm_config(tmp_path, balance="rms", objective="discrete_gradient").make_objective()


@pytest.mark.filterwarnings("ignore:x and dxdt are far from unit scale")
@pytest.mark.parametrize("units, recorded", [("off", "loss_weights"), ("auto", "unit_scales")])
def test_a_group_whose_data_balance_trains_each_run_alone_with_its_weights(tmp_path, units, recorded):
    """Grouped training weighs no components and rescales nothing: where --balance auto balances (the 10 kg
    arm in its own units) or --units auto rescales (the same at the defaults), each run trains alone, as
    ``hnn.run_experiment`` would, so its folder is the lone run's (what auto resolved to recorded)."""
    configs = [_arm_config(tmp_path, model="hnn", mass=10.0, seed=s, units=units) for s in (0, 1)]
    assert hnn.sweeps.group_runs.closed_form_key(configs[0]) is not None and hnn.sweeps.group_runs.closed_form_key(_arm_config(tmp_path, balance="rms")) is None
    folders = hnn.sweeps.group_runs.train_group(configs)
    assert [f.name for f in folders] == [hnn.runs.run_dir(c).name for c in configs]
    assert all(recorded in json.loads((f / "args.json").read_text()) for f in folders)
