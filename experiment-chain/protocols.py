"""The peers' published protocols on pendulum chains, as numbers and functions (docs/peers.md).

- CHNN (Finzi, Wang & Wilson 2020, ``pl_trainer.py`` and the notebook that made their figure):
  rollouts of T = 3 s at dt = 0.03 (100 states, t = 0 included) from 100 test starts; per step
  the relative error e_t = |z^ - z| / (|z^| + |z|) of the Cartesian positions and velocities of
  all bobs; per trajectory the geometric mean exp[(1/T) trapz(log(e_t + 1e-8), dx=dt)]; reported:
  the mean (and median) over trajectories. The chaos floor: the same number for the truth from a
  start moved by 1e-4 N(0, 1) in Cartesian coordinates and projected back onto the rods.
- LNN (Cranmer et al. 2020, the DoublePendulum notebooks): 40 starts, rolled out to t = 100 s on
  ``linspace(0, 100, 1000)``; the error |E(z^_T) - E(z_T)| / 29.4 at the last time, averaged.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.integrate import trapezoid

import hnn

data = hnn.load_task("chain")

# CHNN's pl_trainer.py defaults and ChainPendulum's class attributes
CHNN = {
    "dt": 0.03, "integration_time": 3.0, "points": 100, "snippet_points": 5,
    "n_train": 800, "n_val": 100, "n_test": 100, "seeds": {"train": 0, "val": 1, "test": 2},
    "perturbation": 1e-4, "log_floor": 1e-8, "model_rtol": 1e-7, "train_method": "rk4", "test_method": "dopri5",
    "optimizer": "AdamW", "learn_rate": 3e-3, "weight_decay": 1e-4, "schedule": "cosine to 0",
    "epochs": 2000, "batch_size": 200, "hidden_dim": 256, "layers": 3, "loss": "mae", "g": data.CHNN_G,
}

# their notebooks/pendulum-geom-mean.csv: mean (median) over the 100 test trajectories of the
# per-trajectory geometric mean; "floor" is the perturbed truth of the HNN run (it varies a little
# from run to run: the CHNN runs read 3.53e-4 at N = 3 and 2.49e-4 at N = 5)
CHNN_PUBLISHED = {
    1: {"NeuralODE": (1.09e-3, 2.76e-4), "HNN": (1.80e-4, 1.12e-4), "DeLaN": (4.21e-4, 2.71e-4),
        "CHNN": (7.46e-5, 6.09e-5), "CLNN": (7.40e-5, 5.82e-5), "floor": (4.86e-5, 3.83e-5)},
    2: {"NeuralODE": (1.21e-1, 4.55e-2), "HNN": (1.34e-2, 1.08e-3), "DeLaN": (7.08e-3, 7.50e-4),
        "CHNN": (5.26e-4, 9.34e-5), "CLNN": (1.80e-4, 1.00e-4), "floor": (7.96e-5, 5.72e-5)},
    3: {"NeuralODE": (2.97e-1, 2.76e-1), "HNN": (9.70e-2, 6.11e-2), "DeLaN": (8.72e-2, 4.74e-2),
        "CHNN": (3.34e-3, 2.46e-4), "CLNN": (1.98e-3, 2.46e-4), "floor": (3.55e-4, 9.51e-5)},
    5: {"NeuralODE": (4.48e-1, 4.41e-1), "HNN": (3.57e-1, 3.43e-1), "DeLaN": (3.50e-1, 3.25e-1),
        "CHNN": (3.61e-3, 8.96e-4), "CLNN": (4.30e-3, 8.24e-4), "floor": (2.54e-4, 1.18e-4)},
}

# the LNN notebooks: truth by jax odeint at rtol = atol = 1e-10; derivative training on
# q ~ U[0, 2 pi], qdot ~ U[-10, 10]; test starts q ~ U[0, 2 pi], qdot ~ U[0, 0.1]
LNN = {"t_end": 100.0, "frames": 1000, "starts": 40, "g": data.LNN_G, "truth_rtol": 1e-10,
       "energy_scale": 29.4}
LNN_PUBLISHED = {"LNN": 0.0043, "baseline": 0.074}


def relative_errors(pred: torch.Tensor, true: torch.Tensor, denominator: str = "norms") -> torch.Tensor:
    """Per-step relative errors ``(batch, T)`` of Cartesian paths ``(batch, T, ...)``.

    ``'norms'``: |z^ - z| / (|z^| + |z|), the notebook behind CHNN's published figure and table;
    ``'sum'``: |z^ - z| / |z^ + z|, what their ``pl_trainer.py`` logs (larger once paths part).
    """
    diff = (pred - true).flatten(2).norm(dim=2)
    if denominator == "norms":
        return diff / (pred.flatten(2).norm(dim=2) + true.flatten(2).norm(dim=2))
    if denominator == "sum":
        return diff / (pred + true).flatten(2).norm(dim=2)
    raise ValueError(f"unknown denominator {denominator!r}; choose 'norms' or 'sum'")


def geometric_mean(errors, dt: float = CHNN["dt"], integration_time: float = CHNN["integration_time"],
                   floor: float = CHNN["log_floor"]) -> np.ndarray:
    """Per-trajectory exp[(1/T) trapz(log(e_t + floor), dx=dt)] of errors ``(batch, steps)``, ``(batch,)``.

    As their notebook: the trapezoid runs over every sample, t = 0 included (where a rollout's
    error is 0, so log(floor) = -18.4 enters with weight dt/2), and divides by ``integration_time``
    (3 s), not by the span of the samples (2.97 s).
    """
    logs = np.log(np.asarray(torch.as_tensor(errors).detach().cpu(), dtype=np.float64) + floor)
    return np.exp(trapezoid(logs, dx=dt, axis=-1) / integration_time)


def summary(values) -> dict:
    """``{'mean', 'median', 'n'}`` of per-trajectory numbers; a non-finite one makes the mean inf."""
    v = np.asarray(values, dtype=np.float64)
    return {"mean": float(np.mean(v)), "median": float(np.median(v)), "n": int(v.size)}


def rollout_error(chain, pred: torch.Tensor, true: torch.Tensor, denominator: str = "norms") -> np.ndarray:
    """CHNN's per-trajectory number ``(batch,)`` for observed paths ``z = [q, qdot]`` ``(batch, T, 2N)``."""
    return geometric_mean(relative_errors(chain.cartesian(pred), chain.cartesian(true), denominator))


def chnn_test_starts(chain, count: int = CHNN["n_test"], seed: int = CHNN["seeds"]["test"]) -> torch.Tensor:
    """CHNN's test starts ``(count, 2N)``: as their test loader gives them, the first state of one
    random snippet of each of ``count`` fresh trajectories (so up to 2.85 s into a path)."""
    generator = torch.Generator().manual_seed(seed)
    z0 = data.sample_chnn_starts(chain, count, generator)
    paths = data.trajectories(chain, z0, CHNN["dt"] * np.arange(CHNN["points"]))
    return hnn.objectives.trajectory.sample_snippets(paths, CHNN["snippet_points"], generator)[:, 0]


def perturbed(chain, z0: torch.Tensor, eps: float, generator: torch.Generator) -> torch.Tensor:
    """``z0`` ``(batch, 2N)`` moved by ``eps`` N(0, 1) on every Cartesian coordinate and velocity,
    projected back onto the rods, as their chaos floor."""
    cart = chain.cartesian(z0)
    noise = torch.randn(cart.shape, generator=generator, dtype=torch.float64).to(cart)
    return chain.from_cartesian(chain.project(cart + eps * noise))


def chaos_floor(chain, z0: torch.Tensor, seed: int = 0, eps: float = CHNN["perturbation"]) -> np.ndarray:
    """CHNN's number ``(batch,)`` of the true path from a perturbed start against the true path."""
    t = CHNN["dt"] * np.arange(CHNN["points"])
    true = data.trajectories(chain, z0, t)
    other = data.trajectories(chain, perturbed(chain, z0, eps, torch.Generator().manual_seed(seed)), t)
    return rollout_error(chain, other, true)


def lnn_times() -> np.ndarray:
    """The LNN test grid, ``linspace(0, 100, 1000)`` (1000 samples, 0.1001 s apart)."""
    return np.linspace(0.0, LNN["t_end"], LNN["frames"])


def energy_error(chain, pred_end: torch.Tensor, true_end: torch.Tensor) -> np.ndarray:
    """LNN's |E(z^_T) - E(z_T)| / max |V| ``(batch,)`` for final observed states ``(batch, 2N)``
    (max |V| = 29.4 for their pendulum)."""
    gap = (chain.energy(pred_end.to(torch.float64)) - chain.energy(true_end.to(torch.float64))).abs()
    return gap.detach().cpu().numpy() / chain.max_potential()
