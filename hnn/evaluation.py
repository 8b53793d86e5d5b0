"""Energy-MSE evaluation protocols, as data, and the one function that runs them; the rollout error
of a model by the scene cards' protocol (``rollout_errors``).

Each task declares its protocols in its ``task.py`` (``hnn.PROTOCOLS[task]`` collects them).
Each task has the paper's protocol (what produced the published numbers, quirks included)
and a corrected one. A protocol says how the start states are drawn, the time span and grid,
the solver tolerance, which function is called "energy", and any time rescaling.

Start states come from a box (spring, pend: each coordinate in [0.2, 1] in absolute value),
from the task's own sampler seeded 0..14 (2-body, 3-body), or are the first state of the
measured test segment (real pendulum, compared with the measurements themselves).

The paper's spring protocol rescales the models' time by 1.09 after integrating the truth, and
the rescaling compounds across trials: trial i (0-based) compares the truth on
[0, 21.8 * 1.09^i] with the models on [0, 21.8 * 1.09^(i+1)], point by point. The paper's
pendulum protocol calls q^2 + p^2 the energy. The corrected protocols drop both quirks.
"""
from __future__ import annotations

import contextlib
import contextvars
import copy
import math
import time
import warnings
from dataclasses import asdict, dataclass

import numpy as np
import torch

from .integrators.integrate import rollout
from .interface import Model, declared, gradient_of, step_map_of
from .errors import BudgetError, DivergenceError
from .metrics import energy_mse, path_errors
from .integrators.solvers import get_solver
from .integrators.groups import group_field, group_options
from .progress import Ticker
from .threads import torch_threads


# A protocol's integrator is data: fields ``method`` (a name in ``hnn.SOLVERS``), ``options`` (its
# other rollout options) and ``rtol``/``atol``. These three serve every protocol type that has them.


def check_integrator(protocol) -> None:
    """Fail on an unknown ``method`` (naming the known ones); store a dict of ``options`` as sorted
    pairs, so a frozen protocol stays hashable."""
    get_solver(protocol.method)
    if isinstance(protocol.options, dict):
        object.__setattr__(protocol, "options", tuple(sorted(protocol.options.items())))


def rollout_options(protocol) -> dict:
    """The keywords ``hnn.rollout`` gets: ``method``, its ``options``, and the protocol's
    ``rtol``/``atol`` if the method is adaptive (a fixed-step one has none)."""
    tolerances = {"rtol": protocol.rtol, "atol": protocol.atol} if get_solver(protocol.method).adaptive else {}
    return {"method": protocol.method, **tolerances, **dict(protocol.options)}


def describe_integrator(protocol) -> str:
    """E.g. ``'RK45 rtol 1e-12 atol 1e-06'`` (solve_ivp's default), ``'rk4 dt 0.01'``."""
    solver = get_solver(protocol.method)
    name = solver.describe(dict(protocol.options))
    return f"{name} rtol {protocol.rtol:g} atol {protocol.atol:g}" if solver.adaptive else name


@dataclass(frozen=True)
class EnergyProtocol:
    """How one energy-MSE number is measured.

    Attributes:
        energy: ``'q2+p2'`` (the sum of squares, as the paper's notebooks) or ``'hamiltonian'``
            (the task's true H).
        time_rescale: the paper's spring quirk (1.09, compounding per trial); None for none.
        x0: ``'box'``: each coordinate ~ U[-0.8, 0.8] plus 0.2 sign, so |coordinate| in [0.2, 1],
            from ``RandomState(seed)`` (the original continued the notebook's stream instead, so
            its exact draws cannot be reproduced); ``'seeds'``: ``system.initial_state(i)`` for
            i = 0 .. num_trials - 1; ``'test_segment'``: the measured test trajectory of the
            dataset is the truth, started from its first state on its own (uneven) times, and
            the ± comes from 5 contiguous chunks of its time steps.
        method: the integrator, a name in ``hnn.SOLVERS``; ``dataclasses.replace(protocol,
            method='dopri5')`` swaps it and nothing else. ``rtol``/``atol`` go to adaptive methods.
        options: the method's other ``rollout`` options, e.g. ``{'scipy_method': 'DOP853'}``
            (a dict is stored as sorted ``(name, value)`` pairs, so protocols stay hashable). Box
            and seeds protocols integrate in the rescaled time s = t / span in [0, 1], so a
            fixed-step ``dt`` is a fraction of the span (default: one step per output point).
    """
    name: str
    t_span: tuple[float, float] = (0.0, 20.0)
    num_points: int = 100
    num_trials: int = 15
    rtol: float = 1e-12
    atol: float = 1e-6          # solve_ivp's default, which every original notebook kept
    energy: str = "hamiltonian"
    time_rescale: float | None = None
    x0: str = "box"
    seed: int = 0
    splits: int = 5
    method: str = "solve_ivp"
    options: tuple[tuple[str, object], ...] = ()

    def __post_init__(self):
        check_integrator(self)

    def rollout_options(self) -> dict:
        return rollout_options(self)

    def describe(self) -> str:
        quirks = []
        if self.time_rescale:
            quirks.append(f"model time x{self.time_rescale} compounding per trial")
        if self.x0 == "test_segment":
            where = "the measured test segment, its own times"
        else:
            where = (f"{self.num_trials} trials ({'seeds 0..' + str(self.num_trials - 1) if self.x0 == 'seeds' else 'box'}),"
                     f" t in [{self.t_span[0]:g}, {self.t_span[1]:g}], {self.num_points} points")
        return (f"{self.name}: {where}, {describe_integrator(self)}, energy = {self.energy}"
                + (f", {'; '.join(quirks)}" if quirks else ""))


def start_states(protocol: EnergyProtocol, system=None) -> np.ndarray:
    """``(num_trials, dim)`` start states of a ``'box'`` or ``'seeds'`` protocol."""
    if protocol.x0 == "seeds":
        return np.stack([np.asarray(system.initial_state(i), dtype=np.float64) for i in range(protocol.num_trials)])
    if protocol.x0 != "box":
        raise ValueError(f"unknown start-state rule {protocol.x0!r}")
    rng = np.random.RandomState(protocol.seed)
    x0 = np.empty((protocol.num_trials, 2))
    for i in range(protocol.num_trials):
        y = (rng.rand(2) * 2 - 1) * 0.8
        x0[i] = y + 0.2 * np.sign(y)
    return x0


def _energy(system, protocol: EnergyProtocol, x: torch.Tensor) -> np.ndarray:
    x = x.to(dtype=torch.float64, device="cpu")         # the true H is measured on the CPU, in float64
    if protocol.energy == "q2+p2":
        return (x ** 2).sum(-1).numpy()
    if protocol.energy == "hamiltonian":
        return system.hamiltonian(x).numpy()
    raise ValueError(f"unknown energy {protocol.energy!r}; use 'q2+p2' or 'hamiltonian'")


def _rollout_scaled(f, x0: torch.Tensor, durations: np.ndarray, num_points: int, protocol,
                    group: int = 1, share: int | None = None, **extra) -> torch.Tensor:
    """Trajectories of per-trial length ``durations`` in one batched call.

    Trial i integrates dx/ds = T_i f(x) on s in [0, 1], which is x(T_i s): one shared grid
    for trials whose time spans differ. Equal spans share one ``(1, 1)`` scale, which any method
    can use; unequal ones (the paper's spring rescale) tie a scale to each row, so they need a
    method that passes every row to every call of ``f`` (dopri5 and dop853 are asked to keep
    their finished rows: ``drop_finished=False``).
    ``group``: ``x0`` holds that many models' blocks of trials (``_group_rollout``), each block scaled alike.
    ``share``: as ``_protocol_rollout``'s (a model's rollout; None: the truth's).
    """
    same = bool(np.all(durations == durations[0]))
    scale = torch.as_tensor(durations[:1] if same else np.tile(durations, group), dtype=x0.dtype,
                            device=x0.device)[:, None]
    if not same:
        extra = {**group_options(protocol.method), **extra}

    def scaled(x: torch.Tensor) -> torch.Tensor:
        if len(scale) not in (1, len(x)):
            raise ValueError(f"protocol {protocol.name!r} scales each trial's time differently, but "
                             f"{protocol.method} passed {len(x)} of the {len(scale)} rows to f: use a method "
                             "that keeps every row together (solve_ivp, dopri5, dop853 or a fixed-step one)")
        return scale * f(x)
    return _protocol_rollout(scaled, x0, np.linspace(0.0, 1.0, num_points), protocol, share, **extra)


# a protocol's rollout that needs more field calls than this is scored as failed, not waited for: the true
# systems take 92 (3-body, 15 trials at once) and a sampled 3-body HNN 2924, while a library fit of the
# 3-body, stiff where its polynomial leaves the orbits, passed 20000 on one trial of 15 and did not stop
MAX_FIELD_CALLS = 200_000

# -- the budget of a measurement's rollouts: a quick study's share of seconds, in calls of each field

_BUDGET: contextvars.ContextVar = contextvars.ContextVar("hnn_rollout_budget", default=None)
# the calls of a bounded rollout that time its rate (the rollout's own: the field and the solver's work beside it),
# after its first (which may build the field's kernels)
RATE_CALLS = 20


@contextlib.contextmanager
def rollout_budget(seconds: float | None = None, why: str = "", *, calls: int | None = None):
    """Within it, each model's rollout in ``evaluate_energy`` and ``rollout_errors`` (one model's paths under
    one protocol, or for its rollout error; a group of G models G times it) makes at most ``calls`` calls of its
    field, or, given ``seconds`` instead, the calls that ``seconds`` buys at the rate of its own first calls
    (``RATE_CALLS``, the solver's work between them included), and past them stops with a ``BudgetError``: its
    score says "stopped: over its budget" (``why`` names the budget there), never a number. A budget in
    ``calls`` stops the same models on every box (a quick study's: its share at the reference box's rate); one
    in ``seconds`` depends on the box and its load. The truth's rollouts are not bounded. Outside it, a
    protocol's solve_ivp rollouts stop at ``MAX_FIELD_CALLS``, as always.

        with hnn.evaluation.rollout_budget(calls=20_000, why="the quick study's share"):
            result = hnn.evaluate_energy(system, models, protocol)
    """
    if (seconds is None) == (calls is None):
        raise ValueError(f"rollout_budget(seconds={seconds!r}, calls={calls!r}): give one of them, e.g. "
                         "rollout_budget(calls=20000) (the same on every box) or rollout_budget(2.0) (seconds)")
    if calls is not None:
        if isinstance(calls, bool) or not isinstance(calls, int) or calls < 1:
            raise ValueError(f"rollout_budget(calls={calls!r}): give the field calls one model's rollout may make, "
                             "a positive whole number, e.g. rollout_budget(calls=20000)")
        token = _BUDGET.set(("calls", calls, why))
    else:
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not (0 < seconds < math.inf):
            raise ValueError(f"rollout_budget(seconds={seconds!r}): give the seconds one model's rollout may take, "
                             "a positive finite number, e.g. rollout_budget(2.0)")
        token = _BUDGET.set(("seconds", float(seconds), why))
    try:
        yield
    finally:
        _BUDGET.reset(token)


class _Bounded:
    """The field ``f`` of a rollout that may make ``calls`` calls, or take ``seconds``: then its calls are timed
    from the end of the first to the end of call ``RATE_CALLS + 1``, which fixes ``calls``, the budget those
    seconds buy at that rate (at least those calls, at most ``MAX_FIELD_CALLS``); the call past it raises a
    ``BudgetError``."""

    def __init__(self, f, why: str, seconds: float | None = None, calls: int | None = None):
        self.f, self.seconds, self.why = f, seconds, why
        self.spent, self.calls, self.per_call, self._since = 0, calls, None, None

    def __call__(self, x: torch.Tensor, *rest) -> torch.Tensor:
        self.spent += 1
        if self.calls is not None and self.spent > self.calls:
            rate = ("" if self.seconds is None else
                    f" ({self.seconds:.3g} s at {self.per_call * 1e3:.3g} ms a call)")
            raise BudgetError(f"stopped: over its budget of {self.calls} calls of the field{rate}"
                              f"{', ' + self.why if self.why else ''}", self.calls, self.why)
        out = self.f(x, *rest)
        if self.seconds is None:
            return out
        if self.spent == 1:
            self._since = time.perf_counter()
        elif self.spent == RATE_CALLS + 1:
            self.per_call = max((time.perf_counter() - self._since) / RATE_CALLS, 1e-9)
            self.calls = int(min(MAX_FIELD_CALLS, max(self.spent, self.seconds / self.per_call)))
        return out


def _bounded(f, share: int = 1):
    """``f`` (a field, or a model: its declared ``field`` as a whole) bounded by the ``rollout_budget`` it runs
    in (``share`` models' worth), or ``f`` as it is outside one."""
    budget = _BUDGET.get()
    if budget is None:
        return f
    field = f.field if isinstance(f, Model) else f
    how, amount, why = budget
    if how == "calls":
        return _Bounded(field, why, calls=amount * share)
    return _Bounded(field, why, seconds=amount * share)


def _protocol_rollout(f, x0: torch.Tensor, t_eval: np.ndarray, protocol, share: int | None = None,
                      **extra) -> torch.Tensor:
    """``rollout`` by the protocol's integrator and tolerances, without the float32-tolerance warning; a method
    that takes ``max_calls`` (solve_ivp) stops past ``MAX_FIELD_CALLS`` with a ``DivergenceError``. ``share``:
    a model's rollout (of that many models), bounded by the ``rollout_budget`` it runs in; None: the truth's."""
    if share is not None:
        f = _bounded(f, share)
    with warnings.catch_warnings():
        # the protocols ask float32 models for tight tolerances, as the original did: what that
        # costs in accuracy is a property of the protocol, not news at every evaluation
        warnings.filterwarnings("ignore", message=".*tighter than torch.float32", category=UserWarning)
        # threads=None: evaluate_energy's own count (its batches of 15 trials run on one thread anyway)
        options = protocol.rollout_options()
        if "max_calls" in get_solver(options["method"]).accepts():
            options = {"max_calls": MAX_FIELD_CALLS} | options
        return rollout(f, x0, t_eval, threads=None, **options, **extra)


def _model_rollout(model, run, x0: torch.Tensor, observed: str) -> torch.Tensor:
    """``run(field, start)`` of ``model`` from observed starts ``x0`` in ``observed`` coordinates,
    in the model's own dtype and state, mapped back to observed states ``(batch, T, dim)``."""
    param = next(model.parameters())
    x = declared(model).state_from(x0.to(dtype=param.dtype, device=param.device), observed)
    traj = run(model.time_derivative, x)
    with torch.no_grad():
        return model.observed_from(traj.reshape(-1, traj.shape[-1]), observed).reshape(traj.shape)


def _group_rollout(models: list, run, x0: torch.Tensor, observed: str, protocol) -> list[torch.Tensor]:
    """``_model_rollout`` of each model of a group (one kind and shape): where the protocol's method is
    ``row_wise``, every model's trials in one integration (``hnn.integrators.groups.group_field``: each row its
    own steps, so each path is its model's own up to the batched products' rounding); otherwise one
    model after another. ``run(field, start, group=G, **options)`` integrates ``(G * trials, dim)`` rows."""
    if not get_solver(protocol.method).row_wise:
        return [_model_rollout(m, run, x0, observed) for m in models]
    param = next(models[0].parameters())
    starts = [declared(m).state_from(x0.to(dtype=param.dtype, device=param.device), observed) for m in models]
    traj = run(group_field(models), torch.cat(starts), group=len(models), **group_options(protocol.method))
    traj = traj.reshape(len(models), len(x0), *traj.shape[1:])
    with torch.no_grad():
        return [m.observed_from(t.reshape(-1, t.shape[-1]), observed).reshape(t.shape) for m, t in zip(models, traj)]


def _scored(system, protocol: EnergyProtocol, e_true: np.ndarray, traj: torch.Tensor) -> dict:
    """A model's path ``(trials, T, dim)`` scored against the truth's energies: ``traj``, ``energy``, ``mse``, ``mse_se``."""
    e_model = _energy(system, protocol, traj)
    mse, se = energy_mse(e_true, e_model, protocol.splits)
    return {"traj": traj.to(dtype=torch.float64, device="cpu").numpy(), "energy": e_model, "mse": mse, "mse_se": se}


def evaluate_energy(system, models: dict, protocol: EnergyProtocol, dataset: dict | None = None,
                    observed: str = "canonical", threads: int | None = 1, progress: bool | None = None) -> dict:
    """Run ``protocol`` on the true ``system`` (a task's data module) and each model.

    Args:
        system: has ``hamiltonian(x)`` on ``(batch, dim)`` tensors, and ``dynamics(x)`` (or,
            for ``'seeds'`` protocols, ``initial_state(seed)``) as the protocol needs.
        models: ``{label: model}`` (``hnn.Model``); each model's field is integrated in the
            model's own dtype, as the original did (float32), and in its own state: the starts are
            mapped from ``observed`` coordinates into it and its path back (``hnn.Model.state_from``).
            A label may name a group, a list of models of one kind and shape (a setting's seeds):
            their paths share one integration where the protocol's method is ``row_wise`` (each
            row its own steps: ``hnn.integrators.groups.group_field``) and the truth is integrated once for all.
            A learned map (``hnn.Model.steps``) is scored at its own step over the protocol's span, the
            truth on those times; its ``mse`` is None, with ``why``, where the protocol cannot apply.
        dataset: the task's dataset, for ``'test_segment'`` protocols (``test_x``, ``test_t``).
        observed: the coordinates of the system's states (``dataset["state"]``; ``'canonical'``).
        threads: torch's thread count while it runs (default 1, as ``hnn.train``; the caller's count is
            restored after; None: the caller's as it is).
        progress: as ``hnn.train``'s: None a bar where someone watches (after 2 s) and else a line every
            10 s, one step per path (the truth, then each model); False nothing.

    Returns:
        ``{'protocol': {...}, 'x0': ..., 't_truth': (trials, T), 'truth': (trials, T, dim),
        'energy_truth': (trials, T), and per label: 'traj', 'energy', 'mse', 'mse_se'}``
        (trials = 1 for a test segment).
    """
    paths = 1 + sum(len(m) if isinstance(m, (list, tuple)) else 1 for m in models.values())
    with torch_threads(threads), Ticker(paths, f"energy MSE, {protocol.name} protocol", progress, unit="path") as tick:
        if protocol.x0 == "test_segment":
            return _evaluate_segment(system, models, protocol, dataset, observed, tick)
        return _evaluate_trials(system, models, protocol, observed, tick)


def _diverged(err: DivergenceError) -> dict:
    """A model's score where its rollout blew up or stalled: no energy MSE, and why (as a map's where a protocol
    cannot apply); one stopped at its ``rollout_budget`` says so in ``stopped`` too."""
    out = {"mse": None, "mse_se": None, "why": f"its rollout failed: {err}"}
    return {**out, "stopped": str(err)} if isinstance(err, BudgetError) else out


def _scored_or_diverged(model, run, x0: torch.Tensor, observed: str, protocol, score) -> dict | list[dict]:
    """``score`` of the rollout of a model, or of each of a group's (one integration where it can): a model
    that blows up (a sparse fit's cubic terms) scores ``_diverged``, and a group with one such model is
    rolled out model by model, so that only that one goes without an energy."""
    def alone(m):
        try:
            return score(_model_rollout(m, run, x0, observed))
        except DivergenceError as err:
            return _diverged(err)
    if not isinstance(model, (list, tuple)):
        return alone(model)
    try:
        return [score(traj) for traj in _group_rollout(model, run, x0, observed, protocol)]
    except DivergenceError:
        return [alone(m) for m in model]


def _evaluate_trials(system, models: dict, protocol: EnergyProtocol, observed: str, tick: Ticker) -> dict:
    """``evaluate_energy`` of a ``'box'`` or ``'seeds'`` protocol; ``tick`` advances after each path."""
    x0 = torch.as_tensor(start_states(protocol, system), dtype=torch.float64, device="cpu")
    t0, t1 = protocol.t_span
    trials = np.arange(protocol.num_trials)
    rescale = protocol.time_rescale or 1.0
    # the compounding rescale: truth spans grow by rescale^i, the models' by rescale^(i+1)
    truth_spans = (t1 - t0) * (rescale ** trials if protocol.time_rescale else np.ones_like(trials, float))
    model_spans = truth_spans * rescale
    truth = _rollout_scaled(system.dynamics, x0, truth_spans, protocol.num_points, protocol)
    e_true = _energy(system, protocol, truth)
    out = {"protocol": asdict(protocol), "x0": x0.numpy(), "truth": truth.numpy(), "energy_truth": e_true,
           "t_truth": t0 + truth_spans[:, None] * np.linspace(0, 1, protocol.num_points)}
    tick.advance()

    def run(f, x, group=1, **extra):
        return _rollout_scaled(f, x, model_spans, protocol.num_points, protocol, group, share=group, **extra)
    for label, model in models.items():
        if _is_map(model):
            out[label] = _each(model, lambda m: _map_scored(system, protocol, m, x0, observed))
        else:
            out[label] = _scored_or_diverged(model, run, x0, observed, protocol,
                                             lambda traj: _scored(system, protocol, e_true, traj))
        tick.advance(len(model) if isinstance(model, (list, tuple)) else 1)
    return out


def _evaluate_segment(system, models: dict, protocol: EnergyProtocol, dataset: dict | None, observed: str,
                      tick: Ticker) -> dict:
    """The real pendulum's protocol: integrate from the first measured test state over the
    measured times and compare energies step by step (± over contiguous time chunks)."""
    if dataset is None or "test_t" not in dataset:
        raise ValueError("a 'test_segment' protocol needs the task's dataset with test_x and test_t")
    measured = torch.as_tensor(np.asarray(dataset["test_x"]), dtype=torch.float64, device="cpu")
    t = np.asarray(dataset["test_t"], dtype=np.float64)
    t = t - t[0]
    e_true = _energy(system, protocol, measured)
    out = {"protocol": asdict(protocol), "x0": measured[:1].numpy(), "truth": measured[None].numpy(),
           "energy_truth": e_true[None], "t_truth": t[None]}
    tick.advance()

    def run(f, x, group=1, **extra):
        return _protocol_rollout(f, x, t, protocol, share=group, **extra)

    def scored(traj: torch.Tensor) -> dict:          # one trial, (1, T, dim)
        e_model = _energy(system, protocol, traj[0])
        mse, se = energy_mse(e_true, e_model, protocol.splits)
        return {"traj": traj.to(dtype=torch.float64, device="cpu").numpy(), "energy": e_model[None], "mse": mse,
                "mse_se": se}
    for label, model in models.items():
        if _is_map(model):
            out[label] = _each(model, lambda m: _map_scored(system, protocol, m, measured[:1], observed, t, e_true))
        else:
            out[label] = _scored_or_diverged(model, run, measured[:1], observed, protocol, scored)
        tick.advance(len(model) if isinstance(model, (list, tuple)) else 1)
    return out


# The rollout-error metric's integrator (the scene cards'): the errors it measures are 1e-3 and up, so rtol
# 1e-6 changes them in the third digit at most (checked against rtol 1e-9) at half the cost; a healthy field
# needs under 5000 steps over the cards' horizon (3-body baseline: 4800), while a learned orbit that
# collapses shrinks the step without end: 20000 steps bound it.
ROLLOUT_SOLVER = {"method": "dopri5", "rtol": 1e-6, "atol": 1e-8, "max_iterations": 20_000}
BLOWN_UP = 1e6      # a trajectory that blows up is this far from every true state: e(t) ~ 1 over the horizon


def quiet_rollout(f, x0: torch.Tensor, t, **options) -> torch.Tensor:
    """``hnn.rollout`` without autograd and without its tolerance warnings (a study's float64 states: the
    tolerances it asks for are within reach), on the caller's threads unless ``threads`` is given."""
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rollout(f, x0, t, **{"threads": None, **options})


def model_rollout(f, x0: torch.Tensor, t, options: dict = ROLLOUT_SOLVER) -> tuple[torch.Tensor, int]:
    """``(paths (batch, len(t), dim), how many blew up)`` of the field ``f`` from ``x0`` by ``hnn.rollout`` with
    ``options`` (default ``ROLLOUT_SOLVER``; a learned map takes none: it steps itself at its ``dt``),
    the batch at once, or path by path where the batch fails: a path that blows up or does not finish within
    its step budget is ``BLOWN_UP`` everywhere (unrelated to the truth, e(t) ~ 1 over the whole horizon).
    Within a ``rollout_budget`` the field's calls are bounded, all paths' together: a path stopped by it is
    counted here too (``rollout_errors`` says apart which were stopped)."""
    paths, failed, stopped = _paths(f, x0, t, options)
    return paths, failed + stopped


def _paths(f, x0: torch.Tensor, t, options: dict) -> tuple[torch.Tensor, int, int]:
    """``model_rollout``'s ``(paths, how many blew up, how many its rollout_budget stopped)``."""
    if options is ROLLOUT_SOLVER and step_map_of(f) is not None:     # the default solver is a field's: a map
        options = {}                                                # steps itself, as its caller asked nothing
    if step_map_of(f) is None:      # a learned map makes its own steps, as many as its times: nothing to bound
        f = _bounded(f)
    try:
        return quiet_rollout(f, x0, t, **options), 0, 0
    except DivergenceError:
        pass
    rows, failed, stopped = [], 0, 0
    for i in range(len(x0)):
        try:
            rows.append(quiet_rollout(f, x0[i:i + 1], t, **options)[0])
        except DivergenceError as err:
            stopped += isinstance(err, BudgetError)
            failed += not isinstance(err, BudgetError)
            rows.append(torch.full((len(t), x0.shape[1]), BLOWN_UP, dtype=x0.dtype))
    return torch.stack(rows), failed, stopped


def rollout_errors(f, truth: torch.Tensor, t, threads: int | None = 1, options: dict = ROLLOUT_SOLVER) -> dict:
    """The scene cards' rollout numbers of a model: its field ``f`` (``model.time_derivative``; use a
    ``float64_copy``, as the cards do) rolled out by ``model_rollout`` from every ``truth[:, 0]`` and scored
    against the true paths ``truth`` ``(batch, len(t), dim)`` at times ``t`` (``hnn.metrics.path_errors``):
    ``{"error", "valid_time", ...}`` plus ``blew_up`` (paths that blew up), ``stopped`` (paths stopped by the
    ``rollout_budget`` it runs in: scored as blown up, e(t) ~ 1) and ``seconds`` (the rollout's wall time).
    On ``threads`` torch threads (the caller's count restored after). ``options``: as ``model_rollout``'s (a
    learned map: ``{}``, its own steps; ``t`` then on multiples of its ``dt``)."""
    with torch_threads(threads):
        tic = time.perf_counter()
        pred, failed, stopped = _paths(f, truth[:, 0], t, options)
        seconds = time.perf_counter() - tic
    return {**path_errors(pred, truth, t), "blew_up": failed, "stopped": stopped, "seconds": seconds}


def _is_map(model) -> bool:
    """Whether ``model`` (or a group's first model) is a learned map (``hnn.Model.steps``)."""
    first = model[0] if isinstance(model, (list, tuple)) else model
    return declared(first).steps


def _each(model, score):
    """``score`` of a model, or the list of each of a group's."""
    return [score(m) for m in model] if isinstance(model, (list, tuple)) else score(model)


def _map_scored(system, protocol: EnergyProtocol, model, x0: torch.Tensor, observed: str, t: np.ndarray | None = None,
                e_true: np.ndarray | None = None) -> dict:
    """A learned map scored by ``protocol`` at its own step: rolled out from ``x0`` on ``t`` (the measured
    times, which must lie on its step) or else every step ``model.dt`` over the protocol's span, against
    the truth integrated on the same times (``e_true``: given with ``t``). A protocol that rescales the
    models' time (the paper's spring quirk) or whose times are off the map's step does not apply to a map:
    its ``mse`` is None and ``why`` says so. ``times``: the times scored."""
    if protocol.time_rescale:
        return {"mse": None, "mse_se": None, "why": f"the protocol rescales the models' time by {protocol.time_rescale}; "
                                                    "a map steps only by its own step"}
    if t is None:
        steps = int(np.floor((protocol.t_span[1] - protocol.t_span[0]) / model.dt + 1e-9))
        t = model.dt * np.arange(steps + 1)
        e_true = _energy(system, protocol, _protocol_rollout(system.dynamics, x0, t, protocol))
    try:
        traj = _model_rollout(model, lambda f, x: rollout(f, x, t), x0, observed)
    except ValueError as err:        # measured times off the map's step
        return {"mse": None, "mse_se": None, "why": str(err)}
    # a measured segment's energies are one trajectory's, split into contiguous chunks for the +-
    e_model = _energy(system, protocol, traj[0] if e_true.ndim == 1 else traj)
    mse, se = energy_mse(e_true, e_model, protocol.splits)
    return {"traj": traj.to(dtype=torch.float64, device="cpu").numpy(), "energy": e_model.reshape(len(traj), -1),
            "mse": mse, "mse_se": se, "times": t}


def float64_copy(model: torch.nn.Module) -> torch.nn.Module:
    """A float64 copy of ``model`` in eval mode: tight tolerances are then limited by the solver,
    not by float32 rounding of the trained weights."""
    return copy.deepcopy(model).to(torch.float64).eval()


def gradient_of_h(model):
    """``x -> dH/dx`` ``(batch, 2n)`` of an HNN's learned H: the direction in which H grows fastest."""
    return lambda x: gradient_of(model.hamiltonian, x, create_graph=False)


def energy_bump(model, x0, t_flow: float = 6.0, t_bump: float = 0.1, t_after: float | None = None,
                points: int = 300, rtol: float = 1e-10, atol: float = 1e-10) -> dict:
    """The paper's "add energy" experiment: follow the HNN's symplectic field for ``t_flow``, then
    the plain gradient of its H, dx/dt = dH/dx, for ``t_bump``, then the symplectic field again
    for ``t_after`` (default ``t_flow``). Runs on a float64 copy of ``model`` (anything with
    ``time_derivative``, ``hamiltonian`` and ``baseline``: an HNN or a PixelHNN's latent).

    Returns ``t`` ``(T,)``, ``x`` ``(T, 2n)``, ``stage`` ``(T,)`` (0, 1, 2), the learned ``H``
    along the path, and its mean and spread in the two flow stages (spreads near 0 and a higher
    mean after: the bump stays).
    """
    if not declared(model).conservative:
        raise ValueError(f"the energy bump needs a model with a conserved H; {type(model).__name__} declares "
                         "conservative=False (a baseline has no H to climb)")
    model = float64_copy(model)
    device = next(model.parameters()).device
    x0 = x0.detach().cpu().numpy() if torch.is_tensor(x0) else x0
    x = torch.as_tensor(np.asarray(x0, dtype=np.float64).reshape(1, -1), device=device)
    t_after = t_flow if t_after is None else t_after
    pieces, times, stages, t_start = [], [], [], 0.0
    for stage, (f, span) in enumerate([(model.time_derivative, t_flow), (gradient_of_h(model), t_bump),
                                       (model.time_derivative, t_after)]):
        n = points if stage != 1 else max(20, points // 10)
        t = np.linspace(0.0, span, n)
        with torch.no_grad():
            traj = rollout(f, x, t, rtol=rtol, atol=atol)[0]
        pieces.append(traj.cpu().numpy())
        times.append(t_start + t)
        stages.append(np.full(n, stage))
        x, t_start = traj[-1:], t_start + span
    xs, ts, st = np.concatenate(pieces), np.concatenate(times), np.concatenate(stages)
    with torch.no_grad():
        h = model.hamiltonian(torch.from_numpy(xs).to(device)).cpu().numpy()
    before, after = h[st == 0], h[st == 2]
    return {"t": ts, "x": xs, "stage": st, "H": h, "H_before": float(before.mean()), "H_after": float(after.mean()),
            "H_spread_before": float(np.ptp(before)), "H_spread_after": float(np.ptp(after))}
