"""A two-link planar arm in a vertical plane: a mass matrix that depends strongly on the configuration.

Not one of the paper's six tasks (its ``task.py`` keeps it out of ``analysis/reproduce.py``):
the scene where ``mechanical`` (H = 1/2 p^T M^-1(q) p + V(q)) has to learn a mass matrix that
varies with q, where the model kinds were measured on chains (docs/scenes.md, "The two-link arm").

Two uniform rods (masses m_k in kg, lengths l_k in metres, centre of mass at l_k / 2, moment of
inertia m_k l_k^2 / 12 about it) hinged at a fixed shoulder and at the elbow. Generalized
coordinates in radians: q_1 the upper arm's angle from the downward vertical, q_2 the elbow's
angle *relative to* the upper arm (a robot's joint angles, not the chain task's absolute angles).
With a = I_1 + I_2 + m_1 c_1^2 + m_2 (l_1^2 + c_2^2), b = m_2 l_1 c_2, d = I_2 + m_2 c_2^2
(c_k = l_k / 2, I_k = m_k l_k^2 / 12):

    M(q) = [[a + 2 b cos q_2, d + b cos q_2], [d + b cos q_2, d]]            (kg m^2)
    V(q) = -g [(m_1 c_1 + m_2 l_1) cos q_1 + m_2 c_2 cos(q_1 + q_2)]        (J)
    H(q, p) = 1/2 p^T M(q)^-1 p + V(q),  p = M(q) qdot                        (J, kg m^2 / s)

At the defaults (m = l = 1, g = 9.81) M_11 ranges 4x (0.67 to 2.67) and M^-1's largest entry
4x (3.4 to 13.7) over q_2: the arm folded (q_2 = pi) and stretched (q_2 = 0) are different inertias.

States ``x = [q_1, q_2, p_1, p_2]`` of shape ``(batch, 4)``; the dataset is derivatives of
canonical states drawn at random (``sample_states``: q ~ U[-pi, pi]^2, qdot ~ U[-3, 3]^2 rad/s),
so a field error measures the whole configuration space, not one orbit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

import hnn

NAME = "arm"
QDOT_RANGE = 3.0        # rad/s: start rates ~ U[-3, 3], kinetic and potential energy of one size
ROLLOUT_T = 3.0         # s: held-out rollouts, about two swings of the arm
ROLLOUT_DT = 0.03


@dataclass(frozen=True)
class Arm:
    """A two-link arm of uniform rods: ``masses`` and ``lengths`` (shoulder first), gravity ``g``."""
    masses: tuple[float, float] = (1.0, 1.0)
    lengths: tuple[float, float] = (1.0, 1.0)
    g: float = 9.81

    def __post_init__(self):
        if len(self.masses) != 2 or len(self.lengths) != 2:
            raise ValueError(f"a two-link arm needs 2 masses and 2 lengths, got {self.masses} and {self.lengths}")
        if min(self.masses) <= 0 or min(self.lengths) <= 0:
            raise ValueError(f"masses and lengths must be positive, got {self.masses} and {self.lengths}")

    def constants(self) -> tuple[float, float, float, float, float]:
        """``(a, b, d, k_1, k_2)``: M's constants (module docstring) and the gravity moments
        k_1 = g (m_1 c_1 + m_2 l_1), k_2 = g m_2 c_2 (N m)."""
        (m1, m2), (l1, l2) = self.masses, self.lengths
        c1, c2 = l1 / 2, l2 / 2
        i1, i2 = m1 * l1 ** 2 / 12, m2 * l2 ** 2 / 12
        a = i1 + i2 + m1 * c1 ** 2 + m2 * (l1 ** 2 + c2 ** 2)
        return a, m2 * l1 * c2, i2 + m2 * c2 ** 2, self.g * (m1 * c1 + m2 * l1), self.g * m2 * c2

    def _check(self, x, what: str = "x") -> torch.Tensor:
        x = torch.as_tensor(x)
        if x.dim() != 2 or x.shape[1] != 4:
            raise ValueError(f"{what} must have shape (batch, 4) = [q_1, q_2, p_1, p_2] for the arm, "
                             f"got {tuple(x.shape)}")
        return x

    def mass_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """M(q), ``(batch, 2)`` -> ``(batch, 2, 2)``, symmetric positive definite (kg m^2)."""
        a, b, d, _, _ = self.constants()
        c = torch.cos(q[:, 1])
        m12 = d + b * c
        return torch.stack([torch.stack([a + 2 * b * c, m12], -1), torch.stack([m12, torch.full_like(c, d)], -1)], -2)

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """V(q), ``(batch, 2)`` -> ``(batch,)`` in joules (zero with both links horizontal)."""
        _, _, _, k1, k2 = self.constants()
        return -k1 * torch.cos(q[:, 0]) - k2 * torch.cos(q[:, 0] + q[:, 1])

    def velocities(self, x: torch.Tensor) -> torch.Tensor:
        """``z = [q, qdot]`` of canonical states ``x = [q, p]``, both ``(batch, 4)``."""
        x = self._check(x)
        return torch.cat([x[:, :2], torch.linalg.solve(self.mass_matrix(x[:, :2]), x[:, 2:, None])[..., 0]], 1)

    def momenta(self, z: torch.Tensor) -> torch.Tensor:
        """``x = [q, p]`` of observed states ``z = [q, qdot]``, both ``(batch, 4)``."""
        z = self._check(z, "z")
        return torch.cat([z[:, :2], (self.mass_matrix(z[:, :2]) @ z[:, 2:, None])[..., 0]], 1)

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H(q, p), ``(batch, 4)`` -> ``(batch,)``, in joules."""
        x = self._check(x)
        v = self.velocities(x)[:, 2:]
        return 0.5 * (x[:, 2:] * v).sum(1) + self.potential(x[:, :2])

    def dynamics(self, x: torch.Tensor) -> torch.Tensor:
        """Hamilton's equations in closed form, ``(batch, 4) -> (batch, 4)``.

        dq/dt = M^-1 p = v; dp_k/dt = 1/2 v^T (dM/dq_k) v - dV/dq_k, where only M's q_2 terms vary:
        dp_1/dt = -k_1 sin q_1 - k_2 sin(q_1 + q_2), dp_2/dt = -b sin q_2 (v_1^2 + v_1 v_2) - k_2 sin(q_1 + q_2).
        """
        x = self._check(x)
        _, b, _, k1, k2 = self.constants()
        q1, q2 = x[:, 0], x[:, 1]
        v = self.velocities(x)[:, 2:]
        v1, v2 = v[:, 0], v[:, 1]
        elbow = k2 * torch.sin(q1 + q2)
        dp1 = -k1 * torch.sin(q1) - elbow
        dp2 = -b * torch.sin(q2) * (v1 ** 2 + v1 * v2) - elbow
        return torch.cat([v, torch.stack([dp1, dp2], 1)], 1)

    def rod_kinetic_energy(self, z: torch.Tensor) -> torch.Tensor:
        """T of observed states ``z = [q, qdot]`` ``(batch, 4)`` summed rod by rod from Cartesian
        velocities of the centres of mass and the rods' spins (independent of M's closed form)."""
        (m1, m2), (l1, l2) = self.masses, self.lengths
        q1, q12 = z[:, 0], z[:, 0] + z[:, 1]
        w1, w12 = z[:, 2], z[:, 2] + z[:, 3]
        # d/dt of the centre of mass positions (x right, y up): (l sin th, -l cos th)' = l thdot (cos th, sin th)
        v1 = (l1 / 2) * w1[:, None] * torch.stack([torch.cos(q1), torch.sin(q1)], 1)
        v2 = l1 * w1[:, None] * torch.stack([torch.cos(q1), torch.sin(q1)], 1) \
            + (l2 / 2) * w12[:, None] * torch.stack([torch.cos(q12), torch.sin(q12)], 1)
        spin = m1 * l1 ** 2 / 12 * w1 ** 2 + m2 * l2 ** 2 / 12 * w12 ** 2
        return 0.5 * (m1 * v1.pow(2).sum(1) + m2 * v2.pow(2).sum(1) + spin)


def sample_states(arm: Arm, count: int, generator: torch.Generator) -> torch.Tensor:
    """``count`` canonical states ``x = [q, p]`` ``(count, 4)``, float64: q ~ U[-pi, pi]^2 and
    qdot ~ U[-QDOT_RANGE, QDOT_RANGE]^2 drawn in that order, then p = M(q) qdot."""
    u = torch.rand(count, 4, generator=generator, dtype=torch.float64)
    z = torch.cat([math.pi * (2 * u[:, :2] - 1), QDOT_RANGE * (2 * u[:, 2:] - 1)], 1)
    return arm.momenta(z)


def trajectories(arm: Arm, x0: torch.Tensor, t_eval, rtol: float = 1e-10, atol: float = 1e-10) -> torch.Tensor:
    """True paths ``(batch, len(t_eval), 4)`` of canonical starts ``x0`` ``(batch, 4)``: dopri5 in float64."""
    x0 = arm._check(torch.as_tensor(x0, dtype=torch.float64))
    with torch.no_grad():
        return hnn.rollout(arm.dynamics, x0, t_eval, method="dopri5", rtol=rtol, atol=atol)


def get_dataset(seed: int = 0, n_train: int = 2000, n_test: int = 1000, n_rollouts: int = 16,
                arm: Arm | None = None) -> dict:
    """Canonical states and their true dx/dt, float32: ``x``, ``dxdt`` ``(n_train, 4)``, ``test_x``,
    ``test_dxdt`` ``(n_test, 4)`` (drawn under seeds ``seed`` and ``seed + 1``), and
    ``rollout_x0`` ``(n_rollouts, 4)`` (seed ``seed + 2``) with ``t_eval`` (0 to ROLLOUT_T s)
    for held-out rollouts against ``trajectories``. Cheap (no integration): not cached."""
    for label, value in (("n_train", n_train), ("n_test", n_test), ("n_rollouts", n_rollouts)):
        if not isinstance(value, int) or value < 1:
            raise ValueError(f"{label} must be a positive integer, got {value!r}")
    arm = arm or Arm()
    out = {}
    for split, count, offset in (("", n_train, 0), ("test_", n_test, 1)):
        x = sample_states(arm, count, torch.Generator().manual_seed(seed + offset))
        out[split + "x"] = x.float().numpy()
        out[split + "dxdt"] = arm.dynamics(x).float().numpy()
    out["rollout_x0"] = sample_states(arm, n_rollouts, torch.Generator().manual_seed(seed + 2)).numpy()
    out["t_eval"] = ROLLOUT_DT * np.arange(int(round(ROLLOUT_T / ROLLOUT_DT)) + 1)
    return out
