"""Task 4, two bodies under Newtonian gravity (G = 1, unit masses, no softening).

States are x = [qx_1, qx_2, qy_1, qy_2, px_1, px_2, py_1, py_2], shape (batch, 8); the
physics (H, dynamics, momenta) is ``hnn.orbits.nbody``'s, for any number of bodies. This file holds
the system's constants, its sampler of start states and thin wrappers.

Start states (the original's ``random_config``): body 0 at pos ~ U[0.5, 1.5]^2 (so the
separation is 2|pos|, about 1.4 to 4.2, not the paper's "[0.5, 1.5]"), with the velocity of a
circular orbit about the centre of mass, (-pos_y, pos_x) / (2 |pos|^1.5), scaled by one factor
1 + 0.05 N(0, 1) per orbit; body 1 is minus body 0, so the centre of mass and the total
momentum are zero.
"""
from pathlib import Path

import numpy as np

from hnn.orbits import nbody
from hnn.orbits.nbody import (angular_momentum, dynamics, hamiltonian, kinetic_energy, min_separation,  # noqa: F401
                       potential_energy, total_momentum)

HERE = Path(__file__).resolve().parent
NAME = "2body"
NUM_BODIES = 2
ORBIT_NOISE = 5e-2          # std of the one velocity scale factor per orbit
MIN_RADIUS, MAX_RADIUS = 0.5, 1.5   # range of each coordinate of body 0's position
DEFAULTS = {"num_trials": 1000, "num_points": 50, "t_span": [0.0, 20.0], "test_split": 0.2,
            "rtol": 1e-9, "atol": 1e-6, "min_separation": nbody.TASK_MIN_SEPARATION,
            "orbit_noise": ORBIT_NOISE, "min_radius": MIN_RADIUS, "max_radius": MAX_RADIUS}


def random_config(rng: np.random.RandomState, orbit_noise: float = ORBIT_NOISE, min_radius: float = MIN_RADIUS,
                  max_radius: float = MAX_RADIUS) -> np.ndarray:
    """One start state ``(8,)``; draws rand(2) for the position, then randn() for the speed factor."""
    pos = rng.rand(2) * (max_radius - min_radius) + min_radius
    r = np.sqrt((pos ** 2).sum())
    vel = np.array([-pos[1], pos[0]]) / (2 * r ** 1.5)
    vel = vel * (1 + orbit_noise * rng.randn())
    q = np.stack([pos, -pos])       # (body, xy)
    p = np.stack([vel, -vel])
    return np.concatenate([q[:, 0], q[:, 1], p[:, 0], p[:, 1]])


def initial_state(seed: int) -> np.ndarray:
    """The start state of energy-MSE trial ``seed`` (the original seeded numpy with 0..14)."""
    return random_config(np.random.RandomState(seed))


def get_dataset(seed: int = 0, save_dir=HERE, **params) -> dict:
    """1000 orbits of 50 points on [0, 20] (RK45, rtol 1e-9); the first 20% of rows (orbits 0-199,
    10000 rows) test, the other 40000 train. ``params`` override ``DEFAULTS``.

    Returns float32 ``x``, ``dxdt`` (the analytic derivative at each row), ``test_x``,
    ``test_dxdt``, plus ``dt``, ``t_eval`` and ``resampled`` (orbits redrawn for close encounters,
    ``resampled_close_encounter``, or failed integrations, ``resampled_failed``). Cached in
    ``save_dir`` under a hash of all the params and the seed.
    """
    return nbody.task_dataset(NAME, random_config, DEFAULTS, ("orbit_noise", "min_radius", "max_radius"), seed, save_dir, params)
