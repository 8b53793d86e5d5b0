"""The SympNets protocols (Jin et al. 2020, jpzxshi/sympnets ``pendulum.py`` and ``three_body.py``) and
every model of the map benchmark on them: the learned maps (``hnn.models.maps``) beside our HNN rolled
out by RK4 and by the implicit midpoint rule and the separable HNN by leapfrog, at equal training budget
(the same Adam steps, rate and width, on the same pairs of states one step ``h`` apart).

- pendulum: H = p^2/2 - cos q; sympnets' x0 = [0, 1] is their [p, q] order, so q = 1, p = 0 here;
  h = 0.1; train on the 40 steps from x0, test on the next 100 (one rollout from the 40th state).
  Their data come from a 6th-order Stormer-Verlet with 10 substeps a step; ours from DOP853 at rtol 1e-12.
- three_body: the HNN paper's 3-body generator (experiment-3body's ``random_config``, G = 1, unit masses)
  at h = 0.5: 5000 orbits of 10 steps, 4000 train (40000 pairs), 1000 test (a 10-step rollout from each
  orbit's first state). Ours integrates with RK45 at rtol 1e-9 (the task's generator); theirs with a
  6th-order Stormer-Verlet of 100 substeps a step.

A field model is trained through one step of its integrator at ``h`` (``hnn.objectives.trajectory``: snippets of
two states, squared error, as the maps' ``MapObjective``): the HNN through RK4, the separable HNN through
leapfrog; the HNN is rolled out by RK4 and by the midpoint rule (symplectic for its non-separable H).
"""
from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field

import numpy as np
import torch

import hnn
from hnn.objectives.dgnet import pairs_from_paths
from hnn.objectives.map import MapObjective
from hnn.models.maps import GSympNet, HenonNet, LASympNet
from hnn.objectives.trajectory import TrajectoryObjective


@dataclass(frozen=True)
class Protocol:
    """One protocol: its step ``h``, the models' ``width``, the training budget (``steps`` Adam steps at
    ``learn_rate``, ``batch`` rows a step, None: all) and each map's layers (``maps``: name -> (class
    name, layers, extra keywords))."""
    name: str
    h: float
    width: int
    steps: int
    quick_steps: int
    batch: int | None
    maps: dict = field(default_factory=dict)
    learn_rate: float = 1e-3


# each map of a protocol: (kind label, class, its keywords beyond (input_dim, dt)); "as SympNets" rows are
# the layers and activation of their protocol files, the kind rows our defaults (--map_layers 4, tanh)
PENDULUM = Protocol("pendulum", h=0.1, width=30, steps=10_000, quick_steps=300, batch=None, maps={
    "g_sympnet": (GSympNet, {"width": 30, "layers": 4, "activation": "tanh"}),
    "G-SympNet as SympNets (5 layers, sigmoid)": (GSympNet, {"width": 30, "layers": 5, "activation": "sigmoid"}),
    "LA-SympNet as SympNets (3 x 2, sigmoid)": (LASympNet, {"layers": 3, "sublayers": 2, "activation": "sigmoid"}),
    "henon (2 layers)": (HenonNet, {"width": 30, "layers": 2, "activation": "tanh"}),
})
THREE_BODY = Protocol("three_body", h=0.5, width=50, steps=3000, quick_steps=60, batch=512, maps={
    "g_sympnet": (GSympNet, {"width": 50, "layers": 4, "activation": "tanh"}),
    "G-SympNet as SympNets (20 layers, sigmoid)": (GSympNet, {"width": 50, "layers": 20, "activation": "sigmoid"}),
    "LA-SympNet as SympNets (20 x 4, sigmoid)": (LASympNet, {"layers": 20, "sublayers": 4, "activation": "sigmoid"}),
    "henon (4 layers)": (HenonNet, {"width": 50, "layers": 4, "activation": "tanh"}),
})
PROTOCOLS = {p.name: p for p in (PENDULUM, THREE_BODY)}
# the field models: label -> (how it is built, the integrator it trains through, the one it rolls out with)
FIELDS = {"HNN + RK4": ("hnn", "rk4", "rk4"), "HNN + midpoint": ("hnn", "rk4", "midpoint"),
          "separable + leapfrog": ("separable", "leapfrog", "leapfrog")}
REFERENCE = "HNN + RK4"


def _pendulum_field(x: torch.Tensor) -> torch.Tensor:
    return torch.cat([x[:, 1:], -torch.sin(x[:, :1])], dim=1)


def pendulum_energy(x: torch.Tensor) -> torch.Tensor:
    """H = p^2/2 - cos q of ``x = [q, p]`` ``(..., 2)``."""
    return x[..., 1] ** 2 / 2 - torch.cos(x[..., 0])


def data(protocol: Protocol, save_dir, quick: bool = False) -> dict:
    """``{"pairs": (rows, 2 dim) [x_k, x_{k+1}], "test": (starts, steps + 1, dim) true test paths, "dim"}``, float32."""
    if protocol.name == "pendulum":
        x0 = torch.tensor([[1.0, 0.0]], dtype=torch.float64)        # sympnets' [p, q] = [0, 1]
        path = hnn.rollout(_pendulum_field, x0, protocol.h * np.arange(141), method="dop853", rtol=1e-12,
                           atol=1e-12)[0].float()
        return {"pairs": torch.cat([path[:40], path[1:41]], 1), "test": path[None, 40:], "dim": 2}
    orbits = 250 if quick else 5000
    found = hnn.load_task("3body").get_dataset(num_trials=orbits, num_points=11, t_span=[0.0, 10 * protocol.h],
                                               test_split=0.2, save_dir=save_dir)
    if not math.isclose(found["dt"], protocol.h):
        raise ValueError(f"the 3-body generator gave dt={found['dt']}, not the protocol's {protocol.h}")
    return {"pairs": torch.as_tensor(pairs_from_paths(found["x"], 11)),
            "test": torch.as_tensor(found["test_x"]).reshape(-1, 11, 12), "dim": 12}


def build(protocol: Protocol, label: str, dim: int) -> tuple[torch.nn.Module, object, dict]:
    """``(untrained model, its training loss maker, its rollout options)`` of the row ``label``."""
    if label in protocol.maps:
        cls, kwargs = protocol.maps[label]
        model = cls(dim, dt=protocol.h, **kwargs)
        return model, MapObjective(dt=protocol.h), {}
    kind, train_method, rollout_method = FIELDS[label]
    model = (hnn.build_model(dim, protocol.width, "tanh", False) if kind == "hnn"
             else hnn.SeparableHNN(dim, protocol.width))
    return model, TrajectoryObjective(dt=protocol.h, loss="l2", method=train_method, steps=1), {
        "method": rollout_method, "dt": protocol.h}


def labels(protocol: Protocol) -> list[str]:
    return list(protocol.maps) + list(FIELDS)


def horizon_error(path: torch.Tensor, truth: torch.Tensor) -> float:
    """The median over starts of each start's root mean squared state error over the test steps (after the start)."""
    per_start = (path[:, 1:].double() - truth[:, 1:].double()).pow(2).mean(dim=(1, 2)).sqrt()
    return float(per_start.nan_to_num(nan=float("inf")).median())


def _rollout(model, x0: torch.Tensor, protocol: Protocol, steps: int, options: dict) -> torch.Tensor:
    # a learned orbit may leave every bound: its error is then what the metric says, not an exception
    return hnn.rollout(model, x0, protocol.h * np.arange(steps + 1), max_norm=None, **options)


def _rollout_each(model, x0: torch.Tensor, protocol: Protocol, steps: int, options: dict) -> tuple[torch.Tensor, list]:
    """``(paths, the starts that failed)``: the batch rolled out at once, or start by start where an implicit
    step (the midpoint's) fails to converge on some; a failed start's path is NaN (an infinite error)."""
    try:
        return _rollout(model, x0, protocol, steps, options), []
    except hnn.DivergenceError:
        pass
    paths, failed = [], []
    for i in range(len(x0)):
        try:
            paths.append(_rollout(model, x0[i:i + 1], protocol, steps, options)[0])
        except hnn.DivergenceError:
            failed.append(i)
            paths.append(torch.full((steps + 1, x0.shape[1]), float("nan"), dtype=x0.dtype))
    return torch.stack(paths), failed


def _whole_rollout(model, x0: torch.Tensor, protocol: Protocol, steps: int, options: dict) -> None:
    """One rollout for its time: a batch whose midpoint iteration fails on some rows runs to the end all
    the same (those rows retired), and raises only then."""
    try:
        _rollout(model, x0, protocol, steps, options)
    except hnn.DivergenceError:
        pass


def seconds_per_step(model, x0: torch.Tensor, protocol: Protocol, steps: int, options: dict,
                     repeats: int) -> float:
    """The median over ``repeats`` of one ``hnn.rollout`` over ``steps`` steps from ``x0``, per step (one thread)."""
    _whole_rollout(model, x0, protocol, steps, options)
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        _whole_rollout(model, x0, protocol, steps, options)
        times.append((time.perf_counter() - tic) / steps)
    return statistics.median(times)


def _trained(protocol: Protocol, label: str, seed: int, arrays: dict, steps: int, trained: dict):
    """``(model, its last training loss, training seconds, rollout options)`` of row ``label`` at ``seed``;
    rows that differ only in their rollout (HNN + RK4, HNN + midpoint) share one trained model (``trained``)."""
    torch.manual_seed(seed)
    model, objective, options = build(protocol, label, arrays["dim"])
    key = (FIELDS[label][:2] if label in FIELDS else label, seed)
    if key not in trained:
        pairs = arrays["pairs"]
        tic = time.perf_counter()
        stats = hnn.train(model, pairs, pairs, total_steps=steps, learn_rate=protocol.learn_rate, weight_decay=0.0,
                          batch_size=protocol.batch, seed=seed, loss=objective.loss_for(model), print_every=10 ** 9)
        trained[key] = (model.eval(), stats["train_loss"][-1], time.perf_counter() - tic)
    return (*trained[key], options)


def train_and_measure(protocol: Protocol, label: str, seed: int, arrays: dict, quick: bool,
                      repeats: int, trained: dict) -> tuple[dict, torch.nn.Module]:
    """``(row, model)``: one model of row ``label`` trained at ``seed`` (or taken from ``trained``, the
    models so far) and measured: losses, the test-horizon error, the true energy's largest error over
    the test rollout (pendulum), rollout seconds per step, training seconds."""
    steps = protocol.quick_steps if quick else protocol.steps
    model, train_loss, train_seconds, options = _trained(protocol, label, seed, arrays, steps, trained)
    test = arrays["test"]
    horizon = test.shape[1] - 1
    path, failed = _rollout_each(model, test[:, 0], protocol, horizon, options)
    row = {"label": label, "seed": seed, "params": sum(p.numel() for p in model.parameters()),
           "train_loss": train_loss, "train_seconds": train_seconds, "train_steps": steps + 1,
           "horizon_error": horizon_error(path, test),
           "failed_starts": len(failed),
           "seconds_per_step": seconds_per_step(model, test[:, 0], protocol, horizon, options, repeats)}
    if protocol.name == "pendulum":
        row["energy_error"] = float((pendulum_energy(path[0].double()) - pendulum_energy(test[0].double()))
                                    .abs().max())
    return row, model


def step_and_floor(protocol: Protocol, models: dict, x0: torch.Tensor, rounds: int) -> dict:
    """One step of each map and of the HNN's RK4 alone, as a rollout runs it (no graph, inside
    ``frozen_weights``: the numpy kernels for a few states), against the arithmetic of its products
    (``hnn_analysis.benchmarks.floor``, numpy's ``dot`` competing with torch's), in this process."""
    from hnn_analysis.benchmarks import floor
    from hnn_analysis.benchmarks.benchmark_rollouts import field_products
    out = {}
    for label, model in models.items():
        if label in protocol.maps:
            with torch.no_grad():
                shapes = floor.products(lambda model=model: model.step(x0))     # the torch path records its products

            def step(model=model):
                with torch.no_grad():
                    return model.step(x0)
        elif label == REFERENCE:
            shapes = 4 * field_products("hnn", len(x0), protocol.width, x0.shape[1])
            f = model.field

            def step(f=f):
                with torch.no_grad():
                    return hnn.integrators.rk4_step(f, x0, protocol.h)
        else:
            continue
        with hnn.modes.frozen_weights():
            r = floor.compare(step, shapes, rounds=rounds, warmup=max(10, rounds // 10), block=max(5, rounds // 20),
                              with_numpy=True)
        out[label] = {"step_us": r["step_ms"] * 1e3, "floor_us": r["floor_ms"] * 1e3, "ratio": r["ratio"],
                      "best_ratio": r["best_ratio"], "products": r["products"]}
    return out
