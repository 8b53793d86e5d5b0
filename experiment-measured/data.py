"""Your own measurements: trajectories of any system read from a file (``reader.py``), ready to train on.

    rec = load("osc.csv", time="t", q="x", v="v", trial="run")     # a Recording, in your units
    data = get_dataset("osc.csv", time="t", q="x", v="v", trial="run", test_fraction=0.3)

The state is x = [q, v] (positions and their velocities, ``--v``; the dataset says ``"state":
"velocity"``) or x = [q, p] (canonical momenta, ``--p``), of width 2n for n ``--q`` columns.

**Derivatives** (``derivatives``) are finite differences on the measured, possibly uneven, times,
inside gap-free segments only: a trial is cut wherever a step exceeds ``max_gap`` times its
nominal step (the median step of that trial), and the train / test boundary cuts it too, so no
difference spans a gap, two trials or the split. Inside a segment of three or more samples the
derivative at t_i is that of the parabola through (t_i-1, t_i, t_i+1), second order on uneven
steps (``numpy.gradient`` with the sample times); at a segment's ends the one-sided parabola
through the end and its next two samples; a two-sample segment gets their slope, a lone sample
none (it is left out). Or name the derivative columns yourself (``dxdt``, 2n of them).

**Angles** (``periodic``) are unwrapped within each trial before differencing (so a wrap from
pi to -pi is not a jump), then wrapped to [-pi, pi) in the states the models see.

**Snippets** (``--objective trajectory``): non-overlapping runs of ``snippet_steps + 1``
consecutive samples of one part of one trial whose every step is within ``UNIFORM`` of the
nominal step (the median step over the file), since the rollout steps by one fixed ``dt``; the
angles of a snippet stay continuous from its wrapped first state.

**Split** by time: the last ``test_fraction`` of each trial's rows is held out, never a shuffle.

**Scale** (``Scale``), fit on the training rows: q' = (q - q0) / a, s' = s / b for the second
half s (v or p), and t' = t / tau with tau = a / b. One a for every position and one b for every
velocity or momentum, so Hamilton's equations keep their form: the scaled flow is Hamiltonian
with H' = H / b^2 (a uniform scaling of positions, momenta and time, and a shift of q, are
canonical up to that constant), and with tau = a / b a scaled velocity is still the derivative
of its scaled position. Angles keep radians: with a periodic column, a = 1 and it is not
shifted. Every number the study reports is converted back to your units.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

import hnn

reader = hnn.tasks.load_task("measured", "reader")     # hnn.tasks: no torch before the input is checked

UNIFORM = 0.05          # a snippet's steps may differ from the nominal step by this fraction of it
MIN_ROWS = 2            # a trial's train part and its held-out part need at least this many rows each
# a non-periodic --q column that moves this many turns (2 pi) one way in a trial, at least ONE_WAY of all its
# travel, looks like an unwrapped angle: an oscillating position (a spring's, in pixels) comes back (0.1 or
# less on the archive's files), a rotating arm does not (0.3 to 0.5 on them)
TURNS, ONE_WAY = 2, 0.25
ASSUMES = ("on [q, v] the hnn, separable and dissipative kinds take v for the momentum: they assume p = m v with "
           "one constant mass m for every coordinate (right for a point mass on a spring, equal masses, a rigid "
           "pendulum's angle; wrong for a configuration-dependent mass: use mechanical, which learns M(q), or "
           "second_order)")


@dataclass
class Recording:
    """Measurements in the user's units: times ``t`` ``(N,)``, positions ``q`` ``(N, n)`` (angles
    unwrapped), their velocities or momenta ``s`` ``(N, n)``, ``trial`` ids ``(N,)``, optional
    derivative columns ``dxdt`` ``(N, 2n)``; ``state`` is "velocity" or "canonical"; ``notes``: one
    line each for the user (how the file was read, a position that looks like an unwrapped angle)."""
    path: str
    t: np.ndarray
    q: np.ndarray
    s: np.ndarray
    trial: np.ndarray
    state: str
    q_names: list
    s_names: list
    periodic: np.ndarray          # (n,) bool
    where: list                   # where each row is in the file ("line 12")
    dxdt: np.ndarray | None = None
    sha256: str = ""
    notes: list = field(default_factory=list)

    def trials(self) -> list[np.ndarray]:
        """The row indices of each trial, in file order (a trial's rows are contiguous)."""
        cuts = np.flatnonzero(np.diff(self.trial) != 0) + 1
        return np.split(np.arange(len(self.t)), cuts)


def wrap(q: np.ndarray) -> np.ndarray:
    """Angles to [-pi, pi)."""
    return (q + math.pi) % (2 * math.pi) - math.pi


def load(data, time: str = "t", q: str = "", v: str = "", p: str = "", trial: str = "", periodic: str = "",
         dxdt: str = "") -> Recording:
    """The ``Recording`` that the column flags name in the file ``data`` (comma-separated names)."""
    if not str(data or "").strip():
        raise ValueError("no measurements given: pass --data FILE (.csv, text with a header line, or .npz)")
    q_names, v_names, p_names = reader.names(q), reader.names(v), reader.names(p)
    if not q_names:
        raise ValueError("no position columns: pass --q COLS (comma-separated column names)")
    if bool(v_names) == bool(p_names):
        raise ValueError("name the velocities with --v COLS or the canonical momenta with --p COLS (one of the two)")
    s_names, flag = (v_names, "--v") if v_names else (p_names, "--p")
    if len(s_names) != len(q_names):
        raise ValueError(f"{flag} names {len(s_names)} columns and --q {len(q_names)}; give one {flag} column per "
                         "position, in the same order")
    angles = reader.names(periodic)
    if set(angles) - set(q_names):
        raise ValueError(f"--periodic names {sorted(set(angles) - set(q_names))}, which are not --q columns; "
                         "periodic columns are angles among the positions")
    table = reader.read_table(data)
    t = table.column(time, "--time")
    qs = np.stack([table.column(name, "--q") for name in q_names], axis=1)
    ss = np.stack([table.column(name, flag) for name in s_names], axis=1)
    ids = table.column(trial, "--trial") if trial else np.zeros(len(t))
    deriv = None
    if dxdt:
        d_names = reader.names(dxdt)
        if len(d_names) != 2 * len(q_names):
            raise ValueError(f"--dxdt names {len(d_names)} columns; give {2 * len(q_names)}: d/dt of every --q "
                             f"column, then of every {flag} column")
        deriv = np.stack([table.column(name, "--dxdt") for name in d_names], axis=1)
    where = [table.where(i) for i in range(len(t))]
    seen = set()
    for i in range(len(t)):
        if i and ids[i] != ids[i - 1]:
            if ids[i] in seen:
                raise ValueError(f"{table.path}: {where[i]}: trial {ids[i]:g} starts again after other trials; the "
                                 "rows of one trial must be contiguous (sort the file by trial, then time)")
        elif i and not t[i] > t[i - 1]:
            raise ValueError(f"{table.path}: {where[i]}: time {time}={float(t[i])!r} does not increase within trial "
                             f"{ids[i]:g} (the row before has {float(t[i - 1])!r}); sort each trial by time, drop repeated "
                             "samples, or name the trial column with --trial")
        seen.add(ids[i])
    mask = np.array([name in angles for name in q_names])
    rec = Recording(table.path, t, qs, ss, ids, "velocity" if v_names else "canonical", q_names, s_names, mask,
                    where, deriv, hashlib.sha256(Path(table.path).expanduser().read_bytes()).hexdigest())
    for rows in rec.trials():       # angles as encoders log them may be many turns away; differences need them whole
        rec.q[rows[:, None], np.flatnonzero(mask)] = np.unwrap(qs[rows][:, mask], axis=0)
    rec.notes = table.notes + _angle_hints(rec)
    return rec


def _angle_hints(rec: Recording) -> list[str]:
    """One line naming the non-periodic positions that turn like unwrapped angles (``TURNS``, ``ONE_WAY``)."""
    turning = {}
    for j in np.flatnonzero(~rec.periodic):
        for rows in rec.trials():
            q = rec.q[rows, j]
            net, travel = abs(q[-1] - q[0]), np.abs(np.diff(q)).sum()
            if net >= TURNS * 2 * math.pi and net >= ONE_WAY * travel:
                turning[rec.q_names[j]] = f"{net / (2 * math.pi):.1f} turns in trial {rec.trial[rows[0]]:g}"
                break
    if not turning:
        return []
    said = ", ".join(f"{name!r} ({where})" for name, where in turning.items())
    verb = "moves" if len(turning) == 1 else "move"
    return [f"--q {said} {verb} by whole turns of 2 pi one way, as an unwrapped angle does: if "
            f"{'it is an angle' if len(turning) == 1 else 'they are angles'} in radians, pass --periodic "
            f"{','.join(turning)} (read as a position, an unwrapped angle never comes back and no kind predicts it well)"]



def segments(t: np.ndarray, max_gap: float) -> list[np.ndarray]:
    """Index runs of ``t`` (one trial, increasing) with no step over ``max_gap`` times the median step."""
    if len(t) < 2:
        return [np.arange(len(t))]
    steps = np.diff(t)
    cuts = np.flatnonzero(steps > max_gap * np.median(steps)) + 1
    return np.split(np.arange(len(t)), cuts)


def derivatives(t: np.ndarray, x: np.ndarray, max_gap: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """``(dxdt, ok)``: finite differences of ``x`` ``(N, d)`` at times ``t`` ``(N,)`` (one trial) by the
    module's scheme, and ``ok`` ``(N,)``, False for lone samples between gaps (their rows are NaN)."""
    dxdt = np.full(x.shape, np.nan)
    for seg in segments(t, max_gap):
        if len(seg) >= 3:
            dxdt[seg] = np.gradient(x[seg], t[seg], axis=0, edge_order=2)
        elif len(seg) == 2:
            dxdt[seg] = (x[seg[1]] - x[seg[0]]) / (t[seg[1]] - t[seg[0]])
    return dxdt, np.isfinite(dxdt).all(axis=1)


def split_rows(rec: Recording, test_fraction: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per trial ``(train rows, held-out rows)``: the last ``test_fraction`` of its rows is held out."""
    if not 0 < test_fraction < 1:
        raise ValueError(f"--test_fraction {test_fraction!r}: must lie strictly between 0 and 1 (0.3 holds out "
                         "the last 30% of each trial)")
    parts = []
    for rows in rec.trials():
        n_test = int(round(test_fraction * len(rows)))
        if len(rows) - n_test < MIN_ROWS or n_test < MIN_ROWS:
            raise ValueError(f"{rec.path}: trial {rec.trial[rows[0]]:g} ({rec.where[rows[0]]}) has {len(rows)} rows: "
                             f"too few to split by time into {MIN_ROWS}+ training and {MIN_ROWS}+ held-out rows at "
                             f"--test_fraction {test_fraction:g}; record longer trials, merge them, or drop it")
        parts.append((rows[:len(rows) - n_test], rows[len(rows) - n_test:]))
    return parts


@dataclass(frozen=True)
class Scale:
    """q' = (q - q0) / a, s' = s / b, t' = t / tau, tau = a / b (see the module's docstring)."""
    q0: tuple
    a: float
    b: float
    state: str

    @property
    def tau(self) -> float:
        return self.a / self.b

    @classmethod
    def fit(cls, q: np.ndarray, s: np.ndarray, periodic: np.ndarray, state: str) -> Scale:
        """The scale of training rows ``q``, ``s`` ``(rows, n)``."""
        q0 = np.where(periodic, 0.0, q.mean(axis=0))
        a = 1.0 if periodic.any() else float(np.sqrt(np.mean((q - q0) ** 2)))
        b = float(np.sqrt(np.mean(s ** 2)))
        if not (a > 0 and b > 0):
            raise ValueError(f"the training rows do not move (position scale {a:g}, velocity/momentum scale {b:g}); "
                             "check the --q and --v/--p columns")
        return cls(tuple(float(v) for v in q0), a, b, state)

    def x(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Scaled states ``(rows, 2n)`` of user-unit ``q``, ``s``."""
        return np.concatenate([(q - np.asarray(self.q0)) / self.a, s / self.b], axis=1)

    def dxdt(self, dq: np.ndarray, ds: np.ndarray) -> np.ndarray:
        """Scaled time derivatives of user-unit ones: dq'/dt' = dq/dt tau / a, ds'/dt' = ds/dt tau / b."""
        return np.concatenate([dq * self.tau / self.a, ds * self.tau / self.b], axis=1)

    def positions(self, x: np.ndarray) -> np.ndarray:
        """User-unit positions of scaled states ``(..., 2n)``."""
        n = x.shape[-1] // 2
        return x[..., :n] * self.a + np.asarray(self.q0)

    def to_dict(self) -> dict:
        return {**asdict(self), "tau": self.tau}


def prepared(rec: Recording, rows: np.ndarray, max_gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(t, q, s, dxdt)`` in user units of the samples ``rows`` (one trial's part) that have a derivative."""
    t, q, s = rec.t[rows], rec.q[rows], rec.s[rows]
    if rec.dxdt is not None:
        d = rec.dxdt[rows]
        ok = np.ones(len(rows), bool)
    else:
        d, ok = derivatives(t, np.concatenate([q, s], axis=1), max_gap)
    return t[ok], q[ok], s[ok], d[ok]


def snippets(rec: Recording, scale: Scale, parts: list[np.ndarray], steps: int, dt: float) -> np.ndarray:
    """Flattened snippets ``(k, (steps + 1) * 2n)`` of scaled states from the row sets ``parts`` (module docstring)."""
    n, out = rec.q.shape[1], []
    for rows in parts:
        t, x = rec.t[rows], scale.x(rec.q[rows], rec.s[rows])
        i = 0
        while i + steps < len(rows):
            if np.all(np.abs(np.diff(t[i:i + steps + 1]) - dt) <= UNIFORM * dt):
                snip = x[i:i + steps + 1].copy()
                angles = snip[:, :n][:, rec.periodic]
                snip[:, :n][:, rec.periodic] = angles + (wrap(angles[0]) - angles[0])
                out.append(snip.reshape(-1))
                i += steps + 1
            else:
                i += 1
    if not out:
        raise ValueError(f"{rec.path}: no {steps + 1} consecutive samples of a trial part are {dt:.4g} apart (within "
                         f"{UNIFORM:.0%}); --objective trajectory needs even steps: lower --snippet_steps or use "
                         "--objective derivative")
    return np.stack(out).astype(np.float32)


def get_dataset(data, time: str = "t", q: str = "", v: str = "", p: str = "", trial: str = "", periodic: str = "",
                dxdt: str = "", test_fraction: float = 0.3, max_gap: float = 3.0, snippet_steps: int | None = None) -> dict:
    """Scaled training and held-out rows of the measurements (see the module's docstring).

    Returns float32 ``x``, ``dxdt``, ``test_x``, ``test_dxdt`` ``(rows, 2n)`` (angles wrapped),
    float64 ``t``, ``test_t`` (seconds, your units), ``dt`` (the scaled nominal step), ``t_step`` (the
    nominal step in the units of ``t``: what a learned map's pairs are one step apart by), ``state``,
    ``scale`` (``Scale.to_dict()``), ``periodic`` and ``cache_key`` (the file's name and digest);
    with ``snippet_steps``, ``snippets`` and ``test_snippets`` too (``snippets``).
    """
    if not max_gap >= 1:
        raise ValueError(f"--max_gap {max_gap!r}: must be at least 1 nominal step")
    rec = load(data, time, q, v, p, trial, periodic, dxdt)
    parts = {"train": [], "test": []}
    split = split_rows(rec, test_fraction)
    for train_rows, test_rows in split:
        parts["train"].append(prepared(rec, train_rows, max_gap))
        parts["test"].append(prepared(rec, test_rows, max_gap))
    joined = {k: [np.concatenate(col) for col in zip(*v)] for k, v in parts.items()}
    for part, (t_, *_rest) in joined.items():
        if len(t_) < MIN_ROWS:
            raise ValueError(f"{rec.path}: only {len(t_)} {part} rows have a derivative (every other sample sits "
                             f"alone between gaps larger than --max_gap {max_gap:g} nominal steps); raise --max_gap")
    n = rec.q.shape[1]
    scale = Scale.fit(joined["train"][1], joined["train"][2], rec.periodic, rec.state)
    nominal = float(np.median(np.concatenate([np.diff(rec.t[rows]) for rows in rec.trials()])))
    out = {"dt": nominal / scale.tau, "t_step": nominal, "state": rec.state,
           "scale": scale.to_dict(), "periodic": rec.periodic.tolist(),
           "cache_key": f"{Path(rec.path).name}-{rec.sha256[:12]}"}
    for part, prefix in (("train", ""), ("test", "test_")):
        t_, q_, s_, d_ = joined[part]
        x = scale.x(q_, s_)
        x[:, :n][:, rec.periodic] = wrap(x[:, :n][:, rec.periodic])
        out[prefix + "x"] = x.astype(np.float32)
        out[prefix + "dxdt"] = scale.dxdt(d_[:, :n], d_[:, n:]).astype(np.float32)
        out[prefix + "t"] = t_
        if snippet_steps is not None:
            rows = [pair[0 if part == "train" else 1] for pair in split]
            out[prefix + "snippets"] = snippets(rec, scale, rows, snippet_steps, nominal)
    return out
