"""The numbers of a scene of your own measurements, on the held-out tail of each trial, in your units.

- ``Heldout``: the measured tails, the pairs (start, the sample one horizon later) and the naive
  extrapolation's error q(t) + h v(t) (with momenta, v is the finite-difference dq/dt).
- ``prediction_error``: a model rolled out from every start over its own gap to the later sample
  (they differ on uneven steps), the Euclidean norm of the position error (angles wrapped),
  median and mean over starts.
- ``valid_time``: from a few starts per tail, the first time the position error exceeds
  ``VALID_FRACTION`` of the tail's RMS spread of positions (median over starts).
- ``energy_drift``: with ``--energy EXPR``, |E(predicted, t + h) - E(measured, t)| beside the
  measured |E(t + h) - E(t)|, medians over starts.
- ``equation``: a library fit's equation in your columns and units (the run's scaling undone).

Rollouts run on a float64 copy of the model in its scaled units (``scale.json`` of the run), by
``hnn.evaluation.model_rollout`` (dopri5 rtol 1e-6, the scene cards'); a model of canonical [q, p] on observed
[q, v] starts from its own ``state_from_observed``.
"""
from __future__ import annotations

import math
import time

import numpy as np

import hnn

VALID_FRACTION = 0.1       # a prediction is valid while its position error is under this fraction of the spread
VALID_STARTS = 4           # starts per trial of the valid-time rollouts (evenly over the tail's first half)
MATCH = 0.5                # a later sample counts as "at the horizon" within this many nominal steps
_ENERGY_NAMES = {name: getattr(np, name) for name in ("sin", "cos", "tan", "exp", "log", "sqrt", "abs", "pi",
                                                     "arctan2", "sinh", "cosh", "tanh")}


def wrapped_norm(dq: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """The Euclidean norm over the last axis of position differences, angles wrapped to [-pi, pi)."""
    dq = dq.copy()
    dq[..., periodic] = (dq[..., periodic] + math.pi) % (2 * math.pi) - math.pi
    return np.linalg.norm(dq, axis=-1)


class Heldout:
    """The held-out tails of a ``Recording`` (``data.split_rows``) and the horizon pairs in them."""

    def __init__(self, data, rec, test_fraction: float, horizon: float | None, max_gap: float):
        self.rec, self.tails = rec, [rows for _, rows in data.split_rows(rec, test_fraction)]
        spans = [rec.t[rows[-1]] - rec.t[rows[0]] for rows in self.tails]
        self.horizon = 0.1 * min(spans) if horizon is None else float(horizon)
        starts, ends = [], []
        for rows, span in zip(self.tails, spans):
            t = rec.t[rows]
            nominal = float(np.median(np.diff(t)))
            j = np.clip(np.searchsorted(t, t + self.horizon), 1, len(t) - 1)
            j = np.where(np.abs(t[j - 1] - t - self.horizon) < np.abs(t[j] - t - self.horizon), j - 1, j)
            ok = (np.abs(t[j] - t - self.horizon) <= MATCH * nominal) & (j > np.arange(len(t)))
            if not ok.any():
                raise ValueError(f"{rec.path}: trial {rec.trial[rows[0]]:g} holds out {span:.4g} s ({len(rows)} rows), "
                                 f"too short for --horizon {self.horizon:.4g}: no held-out sample has a measured one "
                                 "that far ahead; lower --horizon or raise --test_fraction")
            starts.append(rows[ok])
            ends.append(rows[j[ok]])
        self.starts, self.ends = np.concatenate(starts), np.concatenate(ends)
        self.deltas = rec.t[self.ends] - rec.t[self.starts]
        # the tails' RMS spread of positions about their means (pooled over the tails): the scale of the valid
        # time's threshold, and of the card's "enough"
        self.spread = float(np.sqrt(np.mean(np.concatenate(
            [np.sum((rec.q[rows] - rec.q[rows].mean(axis=0)) ** 2, axis=1) for rows in self.tails]))))
        self.dq = self._tail_velocity(data, max_gap)
        naive = rec.q[self.starts] + self.deltas[:, None] * self.dq[self.starts]
        self.naive = _summary(wrapped_norm(naive - rec.q[self.ends], rec.periodic))

    def _tail_velocity(self, data, max_gap: float) -> np.ndarray:
        """dq/dt at every row: the velocity columns, or finite differences of q within each tail."""
        if self.rec.state == "velocity":
            return self.rec.s
        dq = np.full(self.rec.q.shape, np.nan)
        for rows in self.tails:
            dq[rows] = data.derivatives(self.rec.t[rows], self.rec.q[rows], max_gap)[0]
        return dq


def _summary(errors: np.ndarray) -> dict:
    return {"median": float(np.median(errors)), "mean": float(np.mean(errors)), "starts": int(len(errors))}


class Model:
    """A trained run as the metrics see it: its float64 field in scaled units and its ``Scale``."""

    def __init__(self, data, directory, scale: dict, state: str):
        model, self.args, self.metrics = hnn.load_run(directory)        # torch loads here, past the input checks
        self.params = sum(p.numel() for p in model.parameters())
        self.model = hnn.evaluation.float64_copy(model)
        self.scale = data.Scale(tuple(scale["q0"]), scale["a"], scale["b"], scale["state"])
        self.observed = state      # the recording's coordinates; the model maps them as it declares

    def rollout(self, rec, rows: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(positions, observed states)`` in your units ``(len(rows), len(t), n)`` / ``(..., 2n)`` from the
        measured states ``rows`` over times ``t`` (seconds from each start, from 0)."""
        import torch

        n = rec.q.shape[1]
        x0 = self.scale.x(rec.q[rows], rec.s[rows])
        x0[:, :n][:, rec.periodic] = (x0[:, :n][:, rec.periodic] + math.pi) % (2 * math.pi) - math.pi
        with torch.no_grad():
            x0 = self.model.state_from(torch.as_tensor(x0, dtype=torch.float64), self.observed)
        t = np.asarray(t, dtype=np.float64) / self.scale.tau
        step = hnn.interface.step_map_of(self.model.field)
        if step is None:
            traj, _ = hnn.evaluation.model_rollout(self.model.field, x0, t)
        else:       # a map steps only by its dt: each time is read at its nearest step (within MATCH of a
            k = np.rint(t / step.dt).astype(np.int64)      # sample step, as the horizon pairs are matched)
            steps = np.arange(k.max() + 1)
            traj, _ = hnn.evaluation.model_rollout(self.model.field, x0, t[0] + step.dt * steps)
            traj = traj[:, k - k[0]]
        with torch.no_grad():
            traj = self.model.observed_from(traj.reshape(-1, 2 * n), self.observed).reshape(traj.shape)
        traj = traj.detach().numpy()
        s = traj[..., n:] * self.scale.b
        return self.scale.positions(traj), np.concatenate([self.scale.positions(traj), s], axis=-1)


def equation(model: Model, rec) -> str | None:
    """A library fit's equation (ours, SINDy's) in your columns and units, or None for a model of no formula:
    the run's scaled coordinates q' = (q - q0) / a, s' = s / b, t' = t / tau undone exactly
    (``hnn.fits.equations``: H = b^2 H', its polynomials expanded; a sine or cosine of a scaled position keeps
    its argument written out, cos(q / a - q0 / a)). On [q, v] the hnn kinds read v as p (unit mass)."""
    n = len(rec.q_names)
    s = model.scale
    frame = hnn.fits.Frame(tuple(rec.q_names) + tuple(rec.s_names), (s.a,) * n + (s.b,) * n,
                           tuple(s.q0) + (0.0,) * n, s.tau)
    try:
        return hnn.fits.equation(model.model, frame)
    except ValueError:      # no library's terms: an MLP, sampled neurons
        return None


def energy_function(expr: str | None, rec):
    """``E(z)`` of observed states ``z`` ``(..., 2n)`` (your units) from ``--energy EXPR`` over the column
    names, or None; a bad expression is a ``ValueError`` naming it."""
    if not expr:
        return None
    names = rec.q_names + rec.s_names

    def energy(z: np.ndarray) -> np.ndarray:
        scope = {**_ENERGY_NAMES, **{name: z[..., i] for i, name in enumerate(names)}}
        return np.broadcast_to(np.asarray(eval(expr, {"__builtins__": {}}, scope), dtype=np.float64), z.shape[:-1])

    try:
        value = energy(np.concatenate([rec.q[:2], rec.s[:2]], axis=1))
    except Exception as err:     # any error of the user's expression is an input error: say which
        raise ValueError(f"--energy {expr!r} does not evaluate on the columns {', '.join(names)} "
                         f"({type(err).__name__}: {err}); write a numpy expression of those names, e.g. "
                         "'0.5*v**2 + 0.5*x**2'") from None
    if not np.all(np.isfinite(value)):
        raise ValueError(f"--energy {expr!r} is not finite on the first rows ({value}); check the expression")
    return energy


def measure(model: Model, held: Heldout, energy=None) -> dict:
    """Every number of one model on the held-out tails (see the module's docstring)."""
    rec = held.rec
    keys = np.round(held.deltas, 9)
    times = np.unique(keys)
    tic = time.perf_counter()
    q_hat, z_hat = model.rollout(rec, held.starts, np.concatenate([[0.0], times]))
    seconds = time.perf_counter() - tic
    column = np.searchsorted(times, keys) + 1
    picked = np.arange(len(held.starts))
    q_end, z_end = q_hat[picked, column], z_hat[picked, column]
    out = {"prediction_error": _summary(wrapped_norm(q_end - rec.q[held.ends], rec.periodic)),
           "rollout_seconds": seconds, "valid_time": valid_time(model, held)}
    if energy is not None:
        z0 = np.concatenate([rec.q, rec.s], axis=1)
        out["energy_drift"] = {"model": float(np.median(np.abs(energy(z_end) - energy(z0[held.starts])))),
                               "measured": float(np.median(np.abs(energy(z0[held.ends]) - energy(z0[held.starts]))))}
    return out


def valid_time(model: Model, held: Heldout) -> dict:
    """Median over starts of the first time the position error exceeds ``VALID_FRACTION`` of the tail's
    RMS spread (``reached`` False where some start never did: then its whole remaining tail counts)."""
    rec, found, never = held.rec, [], 0
    for rows in held.tails:
        q = rec.q[rows]
        spread = float(np.sqrt(np.mean(np.sum((q - q.mean(axis=0)) ** 2, axis=1))))
        for i in np.unique(np.linspace(0, len(rows) // 2, VALID_STARTS).astype(int)):
            t = rec.t[rows[i:]] - rec.t[rows[i]]
            q_hat, _ = model.rollout(rec, rows[i:i + 1], t)
            err = wrapped_norm(q_hat[0] - q[i:], rec.periodic)
            over = np.flatnonzero(err > VALID_FRACTION * spread)
            found.append(t[over[0]] if len(over) else t[-1])
            never += not len(over)
    return {"median": float(np.median(found)), "starts": len(found), "never_exceeded": never}
