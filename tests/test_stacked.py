"""Groups of every kind the studies train (``hnn.trainers.vmap``: torch.func's vmap over a model axis) give
their members' lone runs, and a member that fails is named and dropped while the others go on."""
import dataclasses

import numpy as np
import pytest
import torch

import hnn
from hnn.sweeps.group_runs import train_group, unit_key

SMALL = {"total_steps": 20, "hidden_dim": 16}
CHAIN = {"n_train": 20, "n_test": 5}
CASES = {
    "mechanical": ("spring", {"model": "mechanical"}),
    # [q, qdot] states the kind maps to its own [q, p]: each member is scored by its own map, not the first's
    "mechanical-velocity": ("chain", {"model": "mechanical", "objective": "derivative", **CHAIN}),
    "softplus-adamw-cosine-clip": ("spring", {"model": "hnn", "nonlinearity": "softplus", "optimizer": "adamw",
                                              "schedule": "cosine", "clip_grad": 0.5}),
    "constrained": ("chain", {"model": "constrained", **CHAIN}),
    "trajectory": ("chain", {"model": "hnn", "objective": "trajectory", **CHAIN}),
    "second_order-minibatch": ("chain", {"model": "second_order", "batch_size": 16, **CHAIN}),
    "lagrangian": ("chain", {"model": "lagrangian", "protocol": "lnn", "objective": "derivative", "init": "lnn",
                             "nonlinearity": "softplus", "derivative_loss": "l1", "n_train": 64, "n_test": 16,
                             "batch_size": 16}),
    "discrete_gradient": ("spring", {"model": "hnn", "objective": "discrete_gradient", "nonlinearity": "softplus"}),
    # a learned map: its step is the data's dt, recorded in each member's args; its loss steps it under vmap
    "g_sympnet": ("pend", {"model": "g_sympnet", "map_layers": 3}),
}


def _configs(task, values, save_dir, seeds=(0, 1, 2)):
    return [hnn.tasks.task_config(task, {**SMALL, **values, "seed": s, "save_dir": str(save_dir)}) for s in seeds]


def _group_and_lone(task, configs, tmp_path):
    """``(config, its group run, its lone run)`` (each ``hnn.load_run``'s triple) for ``configs`` trained as one group."""
    data = [c.dataset() for c in configs]
    folders = train_group(configs, data)
    for config, dataset, folder in zip(configs, data, folders):
        lone = hnn.run_experiment(hnn.tasks.task_config(task, {**config.to_dict(), "save_dir": str(tmp_path / "lone")}),
                                  dataset)
        yield config, hnn.load_run(folder), hnn.load_run(lone)


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_stacked_group_equals_its_lone_runs(case, tmp_path):
    task, values = CASES[case]
    configs = _configs(task, values, tmp_path / "group")
    assert unit_key(configs[0])[0] == "vmap" and len({unit_key(c) for c in configs}) == 1
    for _config, (a, _, ma), (b, _, mb) in _group_and_lone(task, configs, tmp_path):
        # float32: vmap's batched kernels sum in other orders than a lone model's, 1e-7 relative a step;
        # 20 Adam steps (the LNN's large init weights most) carry it to at most 2e-5 relative on an AVX2 box
        # and, on an AVX-512 one, 5e-5 of a weight tensor's largest and 1.8e-4 of the LNN's losses (its
        # train loss at a spike of 109, step 5; measured over the 3 seeds at 1 and 2 threads)
        for name, w in a.state_dict().items():
            torch.testing.assert_close(w, b.state_dict()[name], rtol=1e-4, atol=1e-4 * b.state_dict()[name].abs().max())
        np.testing.assert_allclose(ma["history"]["train_loss"], mb["history"]["train_loss"], rtol=1e-3)
        np.testing.assert_allclose(ma["test_loss"], mb["test_loss"], rtol=1e-3)


# the kinds CASES leaves out, but the pixel ones (their renders take minutes; tests/test_pixels.py groups them)
GROUPED_KINDS = sorted(set(hnn.MODEL_KINDS) - {values["model"] for _, values in CASES.values()}
                       - {k for k, row in hnn.MODEL_KINDS.items() if row.grouping == "alone"})


@pytest.mark.parametrize("kind", GROUPED_KINDS)
def test_every_registered_kind_trains_in_a_group_as_its_lone_runs(kind, tmp_path):
    """A kind's author may read a tensor's value where vmap has none (``hnn.Model``'s docstring): every kind
    through a group of 2 seeds (the closed form's or vmap's, as a sweep would choose), against its lone runs,
    on the spring (the chain for a kind that reads velocities or Cartesian states)."""
    task, extra = ("spring", {}) if hnn.MODEL_KINDS[kind].coordinates == "canonical" else ("chain", CHAIN)
    configs = _configs(task, {"model": kind, "total_steps": 5, **extra}, tmp_path / "group", seeds=(0, 1))
    for config, (a, _, ma), (b, _, mb) in _group_and_lone(task, configs, tmp_path):
        for name, w in a.state_dict().items():
            # float32 sums in other orders, as the cases above; but a Henon layer's shift eta and its potential's
            # bias b have gradients of round-off on the spring's symmetric data (1e-9 and 1e-12, the other
            # weights' 1e-4), and Adam scales any gradient to a step of up to the learning rate: round-off
            # decides them, within steps * learn_rate
            ref = b.state_dict()[name]
            noise = name.endswith((".eta", ".potential.b"))
            atol = config.total_steps * config.learn_rate if noise else 1e-4 * float(ref.abs().max())
            torch.testing.assert_close(w, ref, rtol=1e-4, atol=atol)
        np.testing.assert_allclose(ma["test_loss"], mb["test_loss"], rtol=1e-3)


def test_a_stacked_member_that_fails_is_named_and_dropped_while_the_others_train_on(tmp_path, capsys):
    # in the data's own units: --units auto would rescale the blown targets, and that member train alone
    configs = _configs("spring", {"model": "mechanical", "units": "off"}, tmp_path, seeds=(0, 1))
    data = [c.dataset() for c in configs]
    blown = dict(data[1])
    blown["dxdt"] = np.asarray(data[1]["dxdt"]) * 1e30       # finite data, an infinite squared error
    folders = train_group(configs, [data[0], blown])
    assert isinstance(folders[1], hnn.trainers.group_loop.GroupedRunFailed) and folders[1].step == 0
    assert configs[1].name in str(folders[1]) and "not finite" in capsys.readouterr().out
    lone = hnn.run_experiment(configs[0].__class__(**{**configs[0].to_dict(), "save_dir": str(tmp_path / "l")}),
                              data[0])
    for name, w in hnn.load_run(folders[0])[0].state_dict().items():
        torch.testing.assert_close(w, hnn.load_run(lone)[0].state_dict()[name], rtol=1e-4, atol=1e-6)


def test_groups_keep_what_differs_between_models_apart():
    Spring = hnn.load_task("spring", "train").Config
    base = Spring(model="mechanical")
    assert unit_key(base) == unit_key(Spring(model="mechanical", seed=3, train_fraction=0.5, init="zero_bias"))
    for other in (dict(hidden_dim=8), dict(learn_rate=2e-3), dict(model="dissipative"), dict(clip_grad=1.0)):
        assert unit_key(Spring(**{"model": "mechanical", **other})) != unit_key(base), other
    assert unit_key(Spring(model="hnn"))[0] == "closed_form"             # the faster batched closed form
    assert unit_key(hnn.tasks.task_config("pixels", {})) is None          # its objective draws noise of its own


@pytest.mark.parametrize("kind, method", [("hnn", "rk4"), ("separable", "leapfrog"), ("mechanical", "yoshida4"),
                                          ("hnn", "midpoint"), ("baseline", "dopri5"), ("hnn", "dopri5"),
                                          ("mechanical", "dop853"), ("dissipative", "solve_ivp")])
def test_a_group_rolls_out_as_each_of_its_models(kind, method):
    args = {**hnn.tasks.task_config("spring", {"hidden_dim": 16, "model": kind}).to_dict(), "kind": kind}
    models = []
    for seed in range(3):
        torch.manual_seed(seed)
        models.append(hnn.kinds.model_from_args(args).double())
    x0 = torch.randn(3, 4, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    adaptive = hnn.SOLVERS[method].adaptive
    t_eval, options = np.linspace(0.0, 1.0, 5), ({"rtol": 1e-9} if adaptive else {"dt": 0.05})
    stats = {}
    together = hnn.integrators.groups.rollout_group(models, x0, t_eval, method=method, stats=stats, **options)
    assert together.shape == (3, 4, 5, 2)
    calls = []
    for g, model in enumerate(models):
        calls.append({})
        alone = hnn.rollout(model, x0[g], t_eval, method=method, stats=calls[-1], **options)
        # float64: the batched products sum in other orders than one model's, a few ulps a step (the
        # per-row adaptive steps see the same few ulps in their error norms, far from a step's accept line)
        torch.testing.assert_close(together[g], alone, rtol=1e-10, atol=1e-12)
    if hnn.SOLVERS[method].row_wise and not hnn.SOLVERS[method].vmap:
        # one integration of the group's rows: as many batched field calls as its hardest model, not their sum
        assert stats["nfev"] <= max(c["nfev"] for c in calls) + 2 < sum(c["nfev"] for c in calls)


def test_a_group_with_shared_steps_rolls_out_each_model_on_its_own_steps():
    """steps='shared' ties a batch to one step size: a group's models must not share one (each model's rows
    would then be stepped by the others' errors)."""
    args = {**hnn.tasks.task_config("spring", {"hidden_dim": 16}).to_dict(), "kind": "hnn"}
    models = []
    for seed in range(2):
        torch.manual_seed(seed)
        models.append(hnn.kinds.model_from_args(args).double())
    x0 = torch.randn(2, 3, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    t_eval = np.linspace(0.0, 1.0, 5)
    together = hnn.integrators.groups.rollout_group(models, x0, t_eval, method="dopri5", rtol=1e-6, steps="shared")
    for g, model in enumerate(models):
        assert torch.equal(together[g], hnn.rollout(model, x0[g], t_eval, method="dopri5", rtol=1e-6, steps="shared"))


def test_a_sweep_groups_every_kind_on_a_gpu_and_the_closed_form_kinds_on_the_cpu():
    from hnn.sweeps import sweep
    Spring = hnn.load_task("spring", "train").Config

    def jobs(device, model, width=16):
        return [sweep.Job(f"{model}/{s}", "spring", Spring(model=model, seed=s, hidden_dim=width, device=device))
                for s in range(3)]
    sizes = lambda units: sorted(len(u) for u in units)      # noqa: E731
    assert sizes(sweep.plan_units(jobs("cpu", "hnn"))) == [3]                       # closed form: grouped
    assert sizes(sweep.plan_units(jobs("cpu", "mechanical"))) == [1, 1, 1]          # as the docs' runs trained
    assert sizes(sweep.plan_units(jobs("cpu", "mechanical"), group="all")) == [3]
    assert sizes(sweep.plan_units(jobs("cuda", "mechanical"))) == [3]
    assert sizes(sweep.plan_units(jobs("cuda", "hnn", width=200))) == [3]           # any width on a GPU
    assert sizes(sweep.plan_units(jobs("cpu", "hnn", width=200))) == [1, 1, 1]      # compute-bound on a CPU
    assert sizes(sweep.plan_units(jobs("cuda", "mechanical"), group="off")) == [1, 1, 1]


@pytest.mark.parametrize("method", ["solve_ivp", "dopri5", "rk4"])
def test_a_group_is_scored_by_an_energy_protocol_as_each_of_its_models(method):
    spring = hnn.load_task("spring")
    args = {**hnn.tasks.task_config("spring", {"hidden_dim": 16, "model": "mechanical"}).to_dict(), "kind": "mechanical"}
    models = []
    for seed in range(3):
        torch.manual_seed(seed)
        models.append(hnn.kinds.model_from_args(args).double())
    # the paper's protocol: per-trial time scales, so dopri5 must keep every row of the group in every call
    protocol = dataclasses.replace(hnn.tasks.get_protocol("spring", "paper"), num_trials=5, method=method,
                                   **({"rtol": 1e-9} if method != "rk4" else {}))
    together = hnn.evaluate_energy(spring, {"group": models}, protocol)
    alone = [hnn.evaluate_energy(spring, {"model": m}, protocol)["model"] for m in models]
    assert len(together["group"]) == 3
    for mine, own in zip(together["group"], alone):
        if method == "solve_ivp":        # its step is shared by the batch: each model is integrated alone
            np.testing.assert_array_equal(mine["traj"], own["traj"])
        else:   # one integration of the group's rows; float64 products summed in other orders, a few ulps a step
            np.testing.assert_allclose(mine["traj"], own["traj"], rtol=1e-9, atol=1e-11)
        assert mine["mse"] == pytest.approx(own["mse"], rel=1e-7)


def test_a_group_is_scored_on_a_measured_test_segment():
    real = hnn.load_task("real")
    data = {"test_x": np.stack([np.cos(np.linspace(0, 3, 40)), -np.sin(np.linspace(0, 3, 40))], 1),
            "test_t": np.linspace(0, 3, 40)}
    args = {**hnn.tasks.task_config("spring", {"hidden_dim": 16}).to_dict(), "kind": "hnn"}
    models = []
    for seed in range(2):
        torch.manual_seed(seed)
        models.append(hnn.kinds.model_from_args(args).double())
    protocol = dataclasses.replace(hnn.tasks.get_protocol("real", "paper"), method="dopri5", rtol=1e-9)
    together = hnn.evaluate_energy(real, {"group": models}, protocol, data)["group"]
    for mine, model in zip(together, models):
        own = hnn.evaluate_energy(real, {"model": model}, protocol, data)["model"]
        assert mine["traj"].shape == own["traj"].shape == (1, 40, 2)
        np.testing.assert_allclose(mine["traj"], own["traj"], rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize("method", ["solve_ivp", "dopri5"])
def test_a_model_that_blows_up_scores_no_energy_and_its_group_still_scores_the_rest(method):
    # H = p^2/2 - q^4 sends q to infinity in finite time (q'' = 4 q^3), the spring's H does not
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, size=(200, 2))
    fields = {"spring": np.stack([x[:, 1], -x[:, 0]], 1), "blows up": np.stack([x[:, 1], 4 * x[:, 0] ** 3], 1)}
    models = {name: hnn.fit_least_squares("hnn", x, dxdt, fit="library", progress=False)[0].double()
              for name, dxdt in fields.items()}
    spring = hnn.load_task("spring")
    protocol = dataclasses.replace(hnn.tasks.get_protocol("spring", "corrected"), num_trials=5, method=method,
                                   rtol=1e-9)
    group = hnn.evaluate_energy(spring, {"group": [models["spring"], models["blows up"]]}, protocol)["group"]
    alone = hnn.evaluate_energy(spring, {"model": models["spring"]}, protocol)["model"]
    assert group[1]["mse"] is None and group[1]["why"].startswith("its rollout failed") and "diverged" in group[1]["why"]
    # the library recovers the spring's H, so only the integrator's error (rtol 1e-9) is left
    assert group[0]["mse"] == pytest.approx(alone["mse"], rel=1e-7) and alone["mse"] < 1e-9
    # a healthy group of library fits rolls out in one integration (under vmap where the method is row-wise)
    healthy = hnn.evaluate_energy(spring, {"group": [models["spring"], models["spring"]]}, protocol)["group"]
    assert [m["mse"] for m in healthy] == pytest.approx([alone["mse"]] * 2, rel=1e-7)
