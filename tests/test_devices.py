"""Every task, kind and solver on any torch device.

CI has no GPU, so the CPU suite catches a tensor made on the wrong device this way: torch's default
device is set to ``meta`` while the run's config says ``cpu``. A tensor made without an explicit
device then lands on ``meta``, and the first operation that mixes it with the model's CPU tensors,
or reads its value, fails. The rule this enforces: a model's weights are drawn on the CPU (one seed,
the same weights on every device) and moved to the config's device; everything training,
evaluation and rollouts make follows the device of the state or the model they serve. A task's
dataset is made before the block: data modules run on the CPU by design, and ``hnn.train`` moves
their arrays to the model's device.

The tests marked ``cuda`` run the same on a GPU and are skipped where torch sees none.
"""
import contextlib
import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import pytest
import torch

import hnn

CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device here")

# (task, config values): every kind on a task that can train it; the chain carries the minibatch,
# trajectory and Cartesian kinds, the 2-body task minibatches, the spring the discrete-gradient objective
CASES = [
    ("spring", {"model": "hnn"}), ("spring", {"model": "baseline"}), ("spring", {"model": "separable"}),
    ("spring", {"model": "dissipative"}), ("spring", {"model": "mechanical"}),
    ("spring", {"model": "hnn", "objective": "discrete_gradient"}),
    ("pend", {"model": "hnn", "use_rk4": True}), ("real", {"model": "hnn"}),
    ("2body", {"model": "hnn"}), ("arm", {"model": "mechanical"}),
    ("chain", {"model": "constrained"}), ("chain", {"model": "constrained_lagrangian"}),
    ("chain", {"model": "second_order"}), ("chain", {"model": "mechanical"}),
    ("chain", {"model": "hnn", "objective": "trajectory"}),
    ("chain", {"model": "lagrangian", "protocol": "lnn", "objective": "derivative", "init": "lnn",
               "nonlinearity": "softplus", "derivative_loss": "l1"}),
]
SMALL = {"total_steps": 3, "hidden_dim": 8, "print_every": 1}
TASK_SMALL = {"chain": {"n_train": 20, "n_test": 5}}
DATA = Path(tempfile.mkdtemp(prefix="hnn-devices-"))      # one cache of datasets for the module's runs
# the fixed-step solvers' step: the 3-step LNN's field is stiff at its test starts, and the implicit
# midpoint's fixed point (it needs dt x the field's Lipschitz constant below about 2) failed there at
# 5e-3 on an AVX2 box at 1 and 2 threads, where AVX-512 ones converged
DT = 5e-4


@contextlib.contextmanager
def strict_device():
    """Inside: torch's default device is ``meta``, so a tensor made without a device fails on first use."""
    torch.set_default_device("meta")
    try:
        yield
    finally:
        torch.set_default_device(None)


def _config(task: str, values: dict, device: str, save_dir):
    return hnn.tasks.task_config(task, {**SMALL, **TASK_SMALL.get(task, {}), "seed": 1, **values, "device": device,
                                        "save_dir": str(save_dir)})


def _case_id(case):
    task, values = case
    return "-".join([task] + [str(v) for k, v in values.items() if k in ("model", "objective", "use_rk4")])


def _solvers(model) -> list[str]:
    """The registered methods that can step ``model``'s field."""
    carries_h = getattr(hnn.interface.declared(model).field, "hamiltonian", None) is not None
    return [name for name, solver in hnn.SOLVERS.items() if carries_h or not solver.needs_hamiltonian]


def _train_load_roll(task: str, values: dict, device: str, save_dir, strict: bool) -> dict:
    """Train a tiny run on ``device``, reload it there, roll it out by every solver: what each gave."""
    config = _config(task, values, device, DATA)
    data = config.dataset()                      # made and cached on the CPU, outside the strict block
    config = _config(task, values, device, save_dir)
    with strict_device() if strict else contextlib.nullcontext():
        run = hnn.run_experiment(config, data)
        model, args, _ = hnn.load_run(run, device=device)
        start = torch.as_tensor(np.asarray(data["test_x"])[:3], dtype=torch.float32, device=device)
        model_state = hnn.interface.declared(model).state_from(start, hnn.objectives.observed_coordinates(data))
        paths = {}
        for method in _solvers(model):
            # a short span: a 3-step model (the LNN's, say) may blow up over longer ones, a fact of its training
            options = {"dt": DT} if not hnn.get_solver(method).adaptive else {}
            paths[method] = hnn.rollout(model, model_state, np.linspace(0.0, 0.02, 3), method=method, **options)
    assert args["device"] == device
    return paths


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_every_kind_trains_reloads_and_rolls_out_making_nothing_on_the_default_device(case, tmp_path):
    paths = _train_load_roll(*case, device="cpu", save_dir=tmp_path, strict=True)
    assert paths and all(p.device.type == "cpu" and p.shape[:2] == (3, 3) and torch.isfinite(p).all()
                         for p in paths.values())


def test_every_solver_steps_true_dynamics_on_the_state_device_making_nothing_on_the_default_device():
    spring = hnn.load_task("spring")
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.5]], dtype=torch.float64, device="cpu")
    with strict_device():
        for name, solver in hnn.SOLVERS.items():
            if solver.needs_hamiltonian:
                continue
            options = {} if solver.adaptive else {"dt": 0.01}
            path = hnn.rollout(spring.dynamics, x0, np.linspace(0.0, 1.0, 5), method=name, **options)
            assert path.device == x0.device, name
            # the spring's H = q^2 + p^2 turns (q, p) at rate 2: q(t) = q0 cos 2t + p0 sin 2t
            np.testing.assert_allclose(path[:, -1, 0].numpy(), [np.cos(2.0), 0.5 * np.sin(2.0)], atol=1e-3)


def test_the_energy_protocol_runs_making_nothing_on_the_default_device(tmp_path):
    config = _config("spring", {"model": "hnn"}, "cpu", tmp_path)
    run = hnn.run_experiment(config)
    with strict_device():
        model, _, _ = hnn.load_run(run)
        result = hnn.evaluate_energy(hnn.load_task("spring"), {"hnn": model}, hnn.PROTOCOLS["spring"]["paper"])
    assert np.isfinite(result["hnn"]["mse"])


def test_a_group_is_scored_by_a_protocol_making_nothing_on_the_default_device():
    models = [_drawn("mechanical", seed, "cpu") for seed in (0, 1)]
    protocol = dataclasses.replace(hnn.PROTOCOLS["spring"]["paper"], method="dopri5", rtol=1e-6, num_trials=5)
    with strict_device():
        result = hnn.evaluate_energy(hnn.load_task("spring"), {"group": models}, protocol)
    assert all(np.isfinite(r["mse"]) for r in result["group"])


def _drawn(kind: str, seed: int, device: str) -> torch.nn.Module:
    torch.manual_seed(seed)
    return hnn.kinds.model_from_args({**_config("spring", {"model": kind}, "cpu", ".").to_dict(), "kind": kind},
                                     device=device)


def test_a_group_trains_making_nothing_on_the_default_device(tmp_path):
    # the 2-body task's minibatches and input noise: every random draw of a group's step
    configs = [_config("2body", {"batch_size": 8, "input_noise": 0.01, "seed": s}, "cpu", tmp_path) for s in (0, 1)]
    data = [c.dataset() for c in configs]
    with strict_device():
        folders = hnn.sweeps.group_runs.train_group(configs, data)
    assert all(Path(f).is_dir() for f in folders)


def test_a_state_and_a_model_on_different_devices_is_one_error_naming_both():
    model = hnn.kinds.model_from_args({**_config("spring", {}, "cpu", ".").to_dict(), "kind": "hnn"}, device="meta")
    with pytest.raises(ValueError, match=r"x0 is on cpu but the model's weights are on meta.*x0.to\('meta'\)"):
        hnn.rollout(model, torch.zeros(2, 2), [0.0, 0.1], method="rk4")
    for field in (model.time_derivative, model.field):
        with pytest.raises(ValueError, match="x0 is on cpu but the model's weights are on meta"):
            hnn.rollout(field, torch.zeros(2, 2), [0.0, 0.1], method="rk4")


def test_a_model_is_drawn_on_the_cpu_whatever_the_default_device():
    """One seed, one initial model: the weights do not depend on torch's default device."""
    args = {**_config("spring", {}, "cpu", ".").to_dict(), "kind": "hnn"}
    torch.manual_seed(0)
    plain = hnn.kinds.model_from_args(args)
    torch.manual_seed(0)
    with strict_device():
        strict = hnn.kinds.model_from_args(args)
    for a, b in zip(plain.state_dict().values(), strict.state_dict().values()):
        assert b.device.type == "cpu"
        torch.testing.assert_close(a, b, rtol=0, atol=0)


# ---- on a GPU, where one is present ------------------------------------------------------------


@CUDA
@pytest.mark.cuda
@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_every_kind_trains_reloads_and_rolls_out_on_cuda(case, tmp_path):
    paths = _train_load_roll(*case, device="cuda", save_dir=tmp_path, strict=False)
    assert all(p.device.type == "cuda" and torch.isfinite(p).all() for p in paths.values())


@CUDA
@pytest.mark.cuda
def test_every_solver_on_cuda_agrees_with_the_cpu():
    spring = hnn.load_task("spring")
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.5]], dtype=torch.float64)
    for name, solver in hnn.SOLVERS.items():
        if solver.needs_hamiltonian:
            continue
        options = {} if solver.adaptive else {"dt": 0.01}
        cpu = hnn.rollout(spring.dynamics, x0, np.linspace(0.0, 1.0, 5), method=name, **options)
        gpu = hnn.rollout(spring.dynamics, x0.cuda(), np.linspace(0.0, 1.0, 5), method=name, **options)
        assert gpu.device.type == "cuda"
        # float64 on both: the same steps up to the devices' rounding of the same operations
        torch.testing.assert_close(gpu.cpu(), cpu, rtol=1e-9, atol=1e-12)


@CUDA
@pytest.mark.cuda
def test_a_group_on_cuda_equals_its_lone_runs(tmp_path):
    Config = hnn.load_task("spring", "train").Config
    configs = [Config(**SMALL, seed=s, device="cuda", save_dir=str(tmp_path / "group")) for s in (0, 1)]
    folders = hnn.sweeps.group_runs.train_group(configs)
    for config, folder in zip(configs, folders):
        lone = hnn.run_experiment(Config(**SMALL, seed=config.seed, device="cuda", save_dir=str(tmp_path / "lone")))
        a, b = hnn.load_run(folder)[0], hnn.load_run(lone)[0]
        for x, y in zip(a.state_dict().values(), b.state_dict().values()):
            torch.testing.assert_close(x, y, rtol=1e-4, atol=1e-6)     # float32 sums in other orders


@CUDA
@pytest.mark.cuda
def test_a_group_on_cuda_is_scored_as_its_models_on_the_cpu():
    protocol = dataclasses.replace(hnn.PROTOCOLS["spring"]["paper"], method="dopri5", rtol=1e-6, num_trials=5)
    spring = hnn.load_task("spring")
    gpu = hnn.evaluate_energy(spring, {"g": [_drawn("mechanical", s, "cuda") for s in (0, 1)]}, protocol)["g"]
    cpu = [hnn.evaluate_energy(spring, {"m": _drawn("mechanical", s, "cpu")}, protocol)["m"] for s in (0, 1)]
    for a, b in zip(gpu, cpu):
        # float32 fields on two devices (other kernels, other sums) under per-row steps at rtol 1e-6
        np.testing.assert_allclose(a["traj"], b["traj"], rtol=1e-3, atol=1e-4)


def test_the_pixel_autoencoder_trains_and_reloads_making_nothing_on_the_default_device(tmp_path):
    config = hnn.tasks.task_config("pixels", {**SMALL, "device": "cpu", "save_dir": str(tmp_path), "no_eval": True})
    objective = config.make_objective()
    rng = np.random.default_rng(0)          # frames of the task's shape: the device path, not the pictures, is tested
    data = {name: rng.random((12, config.input_dim), dtype=np.float32) for name in objective.arrays}
    with strict_device():
        run = hnn.run_experiment(config, data)
        model, _, _ = hnn.load_run(run)
        z = model.encode(torch.as_tensor(data[objective.arrays[0]][:3], device="cpu"))
        path = hnn.rollout(model.time_derivative, z, np.linspace(0.0, 0.1, 3), method="rk4", dt=0.05)
    assert path.shape == (3, 3, z.shape[1]) and torch.isfinite(path).all()


def test_the_device_is_recorded_but_is_not_what_makes_two_runs_the_same(tmp_path):
    Config = hnn.load_task("spring", "train").Config
    assert Config(device="cuda:1").key() == Config().key() == "cbac7a2b"    # the key saved before this rule
    assert Config(device="cuda:1").identity()["device"] == "cpu"
    run = hnn.run_experiment(Config(**SMALL, save_dir=str(tmp_path)))
    assert hnn.load_run(run)[1]["device"] == "cpu"
