"""Task 4b, three bodies under Newtonian gravity (G = 1, unit masses, no softening).

States are x = [qx_1..qx_3, qy_1..qy_3, px_1..px_3, py_1..py_3], shape (batch, 12); the
physics (H, dynamics, momenta) is ``hnn.orbits.nbody``'s, for any number of bodies. This file holds
the system's constants, its sampler of start states and thin wrappers.

Start states (the original's ``random_config``): an equilateral triangle, body 1 at a
direction from U[-1, 1]^2 scaled to radius r ~ U[0.9, 1.2], bodies 2 and 3 at 120 and 240
degrees; the circular-orbit velocities (body 1's position turned by 90 degrees, times
3^(-1/4) / r^1.5, turned by 120 and 240 degrees for the others), each multiplied
component-wise by 1 + 0.2 U[-1, 1]^2, so the total momentum is not exactly zero.
"""
from pathlib import Path

import numpy as np

from hnn.orbits import nbody
from hnn.orbits.nbody import (angular_momentum, dynamics, hamiltonian, kinetic_energy, min_separation,  # noqa: F401
                       potential_energy, total_momentum)

HERE = Path(__file__).resolve().parent
NAME = "3body"
NUM_BODIES = 3
NU = 2e-1                           # amplitude of the per-component velocity noise
MIN_RADIUS, MAX_RADIUS = 0.9, 1.2   # distance of each body from the centre
DEFAULTS = {"num_trials": 5000, "num_points": 20, "t_span": [0.0, 5.0], "test_split": 0.2,
            "rtol": 1e-9, "atol": 1e-6, "min_separation": nbody.TASK_MIN_SEPARATION,
            "nu": NU, "min_radius": MIN_RADIUS, "max_radius": MAX_RADIUS}


def rotate(v: np.ndarray, theta: float) -> np.ndarray:
    """The 2-vector ``v`` turned counter-clockwise by ``theta`` radians."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def random_config(rng: np.random.RandomState, nu: float = NU, min_radius: float = MIN_RADIUS,
                  max_radius: float = MAX_RADIUS) -> np.ndarray:
    """One start state ``(12,)``; draws rand(2) (direction), rand() (radius), then rand(2) per body."""
    p1 = 2 * rng.rand(2) - 1
    r = rng.rand() * (max_radius - min_radius) + min_radius
    p1 = p1 * r / np.sqrt((p1 ** 2).sum())
    third = 2 * np.pi / 3
    pos = [p1, rotate(p1, third)]
    pos.append(rotate(pos[1], third))
    # the circular speed of an equilateral triangle of unit masses: sqrt(sin(pi/3) / (2 cos^2(pi/6))) = 3^(-1/4)
    v1 = rotate(p1, np.pi / 2) / r ** 1.5 * np.sqrt(np.sin(np.pi / 3) / (2 * np.cos(np.pi / 6) ** 2))
    vel = [v1, rotate(v1, third)]
    vel.append(rotate(vel[1], third))
    vel = [v * (1 + nu * (2 * rng.rand(2) - 1)) for v in vel]
    q, p = np.stack(pos), np.stack(vel)    # (body, xy)
    return np.concatenate([q[:, 0], q[:, 1], p[:, 0], p[:, 1]])


def initial_state(seed: int) -> np.ndarray:
    """The start state of energy-MSE trial ``seed`` (the original seeded numpy with 0..14)."""
    return random_config(np.random.RandomState(seed))


def get_dataset(seed: int = 0, save_dir=HERE, **params) -> dict:
    """5000 orbits of 20 points on [0, 5] (RK45, rtol 1e-9); the first 20% of rows (orbits 0-999,
    20000 rows) test, the other 80000 train. ``params`` override ``DEFAULTS``.

    Returns float32 ``x``, ``dxdt`` (the analytic derivative at each row), ``test_x``,
    ``test_dxdt``, plus ``dt``, ``t_eval`` and ``resampled`` (orbits redrawn for close encounters,
    ``resampled_close_encounter``, or failed integrations, ``resampled_failed``). Cached in
    ``save_dir`` under a hash of all the params and the seed.
    """
    return nbody.task_dataset(NAME, random_config, DEFAULTS, ("nu", "min_radius", "max_radius"), seed, save_dir, params)
