"""The stress study's grid (``analysis/stress.py`` is its command): every kind fit on three scenes at the
extremes of units, masses and precision, the nominal models' rollouts at long horizons and large steps, and
a heavy mass.

Scenes (the truth in closed form, states drawn at random, dx/dt exact):

- ``spring``: H = p^2 / (2 m) + k q^2 / 2 (m = k = 1), q ~ N(0, 1), p ~ N(0, 1);
- ``arm``: the two-link arm of ``experiment-arm`` (1 kg, 1 m links; q in radians, read as angles);
- ``masses``: two bodies on a line, masses 1 and 1 (the mass ratio cells: 1000), held by unit springs.

Each kind is fit to dx/dt by ``hnn.train`` at one small budget (``BUDGET``) at its defaults: the model in
``hnn.units.Rescaled`` (``--units auto`` rescales the data whose sizes lie outside its bounds, per
coordinate pair where one scale cannot serve) and ``--balance auto``, in the coordinates it reads:
canonical [q, p] (hnn, baseline, separable, dissipative, mechanical, and the constrained kind as point
bodies on a line without rods) or [q, qdot] (second_order, the LNN, the constrained LNN). The constrained
kinds model point bodies, not the arm's rods. Its error is unit-free: the mean over components of
|f_j - f_true_j| / |f_true_j| on held-out states. Rows (``CELLS``):

- **units**: q, p or t in units 10^-3 or 10^3 times the scene's (q' = s q with p' = p / s, so
  Hamilton's equations hold with the same H; p' = s p with H' = s H, a mass unit; t' = s t with
  H' = H / s); **float64** training; **mass** ratio 10^3 (the spring's m / k, the arm's forearm
  against its upper arm, the second body against the first);
- **--units off**: each unit change and the mass ratio again in the data's own units (the plain model,
  ``units='off'``: the default before), what the rescaling undoes; on the two masses also the mass ratio
  rescaled with one scale for all q and one for all p (``ONE_SCALE``) against one per pair;
- **horizon** (spring): the nominal model rolled out by RK4 at dt = 0.1 for ``HORIZON`` steps, the
  true energy's largest relative change along it against the same over 1000 steps;
- **dt** (spring): RK4 at omega dt = 2.5 and 3.0 (its stability limit is 2.83) over 100 steps,
  the energy change against omega dt = 0.1's;
- **heavy mass**: one degree of freedom whose dp/dt is 500x its dq/dt, the mechanical kind and the HNN at
  the defaults and in the data's units, over seeds (``heavy``).

A cell **works** if its number is within 2x of the kind's nominal, **degrades** (its number and the
factor) otherwise, **stops** when training or the rollout raised (its error's first words); a
training that warned (data auto would rescale, trained as given: ``hnn.training``) or a rollout that warned (dt past
RK4's stability limit on the model's fastest mode: ``hnn.integrators.stability``) is marked ``(warned)``,
a cell that auto rescaled ``(rescaled)``.
"""
from __future__ import annotations

import math
import time
import warnings

import numpy as np
import torch

import hnn
from hnn.integrators.stability import StepSizeWarning
from hnn.models import ConstraintGraph
from hnn.threads import torch_threads
from hnn_analysis import plan
from hnn_analysis.commands import run_tasks

arm_data = hnn.load_task("arm")
# the kinds fit on canonical [q, p] (the constrained kind as bodies on a line: [x, p]) and on [q, qdot]
CANONICAL = ("hnn", "baseline", "separable", "dissipative", "mechanical", "constrained")
VELOCITY = ("second_order", "lagrangian", "constrained_lagrangian")
KINDS = CANONICAL + VELOCITY
# kinds of point bodies (a constraint graph of the scene's bodies): the arm's links are rods, not points
POINT_BODIES = ("constrained", "constrained_lagrangian")
# what a kind trains with beyond the budget: the LNN as the peers' table trains it on the chains (softplus,
# its init convex in qdot: analysis/chains/peer_plan.py); at the kind's defaults (tanh, orthogonal) it does
# not fit these scenes at this budget (field error 5.1 on the spring, 3.2 on the arm, 25 on the two masses,
# against 0.029, 0.065 and 0.027 so; measured at seed 0)
KIND_SETTINGS = {"lagrangian": {"nonlinearity": "softplus", "init": "lnn_convex"}}
BUDGET = {"steps": 600, "hidden": 64, "rows": 500, "learn_rate": 3e-3}
QUICK = {"steps": 150, "hidden": 32, "rows": 200, "learn_rate": 1e-2}
PRECISION_SEEDS = (0, 1, 2)
HEAVY_SEEDS = (0, 1, 2)
# an error at or above this is no fit (a zero field scores 1), whatever its nominal: never "works"
NO_FIT = 0.5
# a rescaled cell says how far its widest column stays from unit size where that is over this factor
WIDEST = 3.0
HORIZON, QUICK_HORIZON = 100_000, 1_000
# row -> (scale of q, of p, of t, float64, mass ratio); each trained at hnn.train's defaults (units and
# balance auto: auto rescales the cells whose sizes lie outside its bounds, hnn.units.AUTO_FAR)
CELLS = {"nominal": (1, 1, 1, False, 1), "q x1e-3": (1e-3, 1e3, 1, False, 1), "q x1e3": (1e3, 1e-3, 1, False, 1),
         "p x1e-3": (1, 1e-3, 1, False, 1), "p x1e3": (1, 1e3, 1, False, 1), "t x1e-3": (1, 1, 1e-3, False, 1),
         "t x1e3": (1, 1, 1e3, False, 1), "float64": (1, 1, 1, True, 1), "mass ratio 1e3": (1, 1, 1, False, 1e3)}
# the same cells in the data's own units (--units off, the default before): what the rescaling undoes
OFF = ", --units off"
UNITS_OFF = {f"{cell}{OFF}": cell for cell in ("q x1e-3", "q x1e3", "p x1e-3", "p x1e3", "t x1e-3", "t x1e3",
                                               "mass ratio 1e3")}
# the two masses' heavy cell rescaled with one scale for all q and one for all p, against one per pair
ONE_SCALE = "mass ratio 1e3, one scale"
GRID_CELLS = tuple(CELLS) + tuple(UNITS_OFF)
QUICK_CELLS = ("nominal", "p x1e3", f"p x1e3{OFF}", "t x1e-3", "mass ratio 1e3")


def _spring(rows: int, seed: int, mass_ratio: float) -> dict:
    """Canonical states and dx/dt of the spring (m = mass_ratio, k = 1), float64, and its [q, qdot] twin."""
    g = torch.Generator().manual_seed(seed)
    m = float(mass_ratio)
    x = torch.randn(rows, 2, generator=g, dtype=torch.float64) * torch.tensor([1.0, math.sqrt(m)], dtype=torch.float64)
    dx = torch.stack([x[:, 1] / m, -x[:, 0]], 1)
    z = torch.stack([x[:, 0], x[:, 1] / m], 1)
    return {"x": x, "dxdt": dx, "z": z, "dzdt": torch.stack([z[:, 1], -x[:, 0] / m], 1), "periodic": False}


def _masses(rows: int, seed: int, mass_ratio: float) -> dict:
    """Two bodies on a line, masses 1 and ``mass_ratio``, held by unit springs (wall-body 1, body 1-body 2):
    H = p1^2 / 2 + p2^2 / (2 m2) + x1^2 / 2 + (x2 - x1)^2 / 2, states at random (p_i ~ sqrt(m_i)), float64."""
    g = torch.Generator().manual_seed(seed)
    m = torch.tensor([1.0, float(mass_ratio)], dtype=torch.float64)
    q, p = torch.randn(rows, 2, generator=g, dtype=torch.float64), torch.randn(rows, 2, generator=g, dtype=torch.float64)
    p = p * m.sqrt()
    force = torch.stack([-q[:, 0] + (q[:, 1] - q[:, 0]), -(q[:, 1] - q[:, 0])], 1)
    v = p / m
    return {"x": torch.cat([q, p], 1), "dxdt": torch.cat([v, force], 1), "z": torch.cat([q, v], 1),
            "dzdt": torch.cat([v, force / m], 1), "periodic": False}


def _arm(rows: int, seed: int, mass_ratio: float) -> dict:
    arm = arm_data.Arm((1.0, float(mass_ratio)))
    x = arm_data.sample_states(arm, rows, torch.Generator().manual_seed(seed))
    dx = arm.dynamics(x)
    z, dz = torch.func.jvp(arm.velocities, (x,), (dx,))        # d/dt [q, qdot] along the flow
    return {"x": x, "dxdt": dx, "z": z, "dzdt": dz, "periodic": True}


# scene -> (its data, its bodies as point masses for the constrained kinds: no rods, or None: not points)
SCENES = {"spring": (_spring, ConstraintGraph(1, 1)), "arm": (_arm, None), "masses": (_masses, ConstraintGraph(2, 1))}
# the cells of each scene (the two masses: the mass ratio that one scale for all p cannot serve)
SCENE_CELLS = {"masses": ("nominal", "mass ratio 1e3", ONE_SCALE, f"mass ratio 1e3{OFF}")}


def applies(kind: str, scene: str) -> bool:
    """Whether ``kind`` models ``scene``: the constrained kinds need point bodies (not the arm's rods)."""
    return kind not in POINT_BODIES or SCENES[scene][1] is not None


def _in_units(data: dict, cq: float, cp: float, ct: float) -> dict:
    """The scene's arrays in units where q, p and t read ``cq``, ``cp``, ``ct`` times their values."""
    n = data["x"].shape[1] // 2
    xs = torch.tensor([cq] * n + [cp] * n, dtype=torch.float64)
    zs = torch.tensor([cq] * n + [cq / ct] * n, dtype=torch.float64)
    return {**data, "x": data["x"] * xs, "dxdt": data["dxdt"] * xs / ct, "z": data["z"] * zs, "dzdt": data["dzdt"] * zs / ct}


def field_error(pred: torch.Tensor, true: torch.Tensor) -> float:
    """Mean over components of |pred_j - true_j| / |true_j| (column norms): the same in any units."""
    return float(((pred - true).norm(dim=0) / true.norm(dim=0)).mean())


def _base_cell(cell: str) -> str:
    return cell.removesuffix(", one scale") if cell == ONE_SCALE else UNITS_OFF.get(cell, cell)


def fit(kind: str, scene: str, cell: str, budget: dict, seed: int = 0) -> tuple[object, dict]:
    """``(model, row)``: ``kind`` trained on ``scene`` under ``cell`` by ``hnn.train`` at its defaults (the
    model in ``hnn.units.Rescaled``, which auto rescales or leaves; a ``--units off`` cell: the plain model,
    units='off'); the row has its error or its stop, and the scales auto chose."""
    off = cell in UNITS_OFF
    cq, cp, ct, wide, ratio = CELLS[_base_cell(cell)]
    maker, bodies = SCENES[scene]
    data = {split: _in_units(maker(budget["rows"], seed + offset, ratio), cq, cp, ct)
            for split, offset in (("train", 0), ("test", 1))}
    x_key, y_key = ("z", "dzdt") if kind in VELOCITY else ("x", "dxdt")
    dtype = torch.float64 if wide else torch.float32
    torch.manual_seed(seed)
    model = hnn.kinds.model_from_args({"kind": kind, "input_dim": data["train"]["x"].shape[1], "periodic":
                                       data["train"]["periodic"], "hidden_dim": budget["hidden"],
                                       "dtype": "float64" if wide else "float32",
                                       "constraints": bodies.to_dict() if kind in POINT_BODIES else None,
                                       **KIND_SETTINGS.get(kind, {})})
    x, y = (data["train"][k].to(dtype) for k in (x_key, y_key))
    row = {"kind": kind, "scene": scene, "cell": cell}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if not off:     # hnn.train's defaults: the scales auto picks (1 where it leaves the data), fit there
                coordinates = "velocity" if kind in VELOCITY else "canonical"
                one = hnn.units.fit_scales(x, y, coordinates, bool(getattr(model, "periodic", False)), per_pair=False)
                model = hnn.units.Rescaled(model, one if cell == ONE_SCALE else None)
            hnn.train(model, x, y, total_steps=budget["steps"], learn_rate=budget["learn_rate"], seed=seed,
                      progress=False, units="off" if off else "auto", threads=None)
            with torch.no_grad():
                pred = model.time_derivative(data["test"][x_key].to(dtype)).double()
            row["error"] = field_error(pred, data["test"][y_key])
        except (hnn.DivergenceError, ValueError) as err:
            row["stop"] = f"{type(err).__name__}: {str(err)[:240]}"
    scales = getattr(model, "scales", None)
    if scales is not None and scales.to_dict() != {"q": 1.0, "p": 1.0, "t": 1.0}:
        row["scales"] = scales.to_dict()
    # the column of the data the network fits (in the scales' units) farthest from RMS 1, as a factor
    seen = np.concatenate(scales.to_canonical(x, y, "velocity" if kind in VELOCITY else "canonical"), 1) \
        if scales is not None else np.concatenate([x.double().numpy(), y.double().numpy()], 1)
    row["widest"] = float(np.exp(np.abs(np.log(np.sqrt((seen ** 2).mean(0)))).max()))
    row["warned"] = sorted({"x, dxdt" for w in caught if str(w.message).startswith("x and dxdt are")})
    return model, row


def _spring_energy(states: torch.Tensor) -> torch.Tensor:
    """The true energy of spring states ``(..., 2)`` (m = k = 1: the same in [q, p] and [q, qdot])."""
    return 0.5 * (states[..., 0] ** 2 + states[..., 1] ** 2)


def energy_change(model, kind: str, steps: int, dt: float, seed: int = 0) -> dict:
    """Largest relative change of the spring's true energy along the model's RK4 rollout from 4 starts."""
    x0 = torch.randn(4, 2, generator=torch.Generator().manual_seed(seed + 7), dtype=torch.float64)
    param = next(model.parameters())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StepSizeWarning)
        try:
            path = hnn.rollout(model.time_derivative, x0.to(param.dtype), dt * np.arange(steps + 1), method="rk4")
            E = _spring_energy(path.double())
            row = {"error": float(((E - E[:, :1]).abs() / E[:, :1]).max())}
        except hnn.DivergenceError as err:
            row = {"stop": f"DivergenceError: {str(err)[:240]}"}
    if any(issubclass(w.category, StepSizeWarning) for w in caught):
        row["warned"] = ["dt past RK4's stability limit"]
    return row


def outcome(row: dict, nominal: dict | None) -> str:
    off_scale = [w for w in row.get("warned", ()) if not w.startswith("dt")]
    said = ([f"{', '.join(off_scale)} off unit scale"] if off_scale else []) + [w for w in row.get("warned", ())
                                                                               if w.startswith("dt")]
    warned = f" (warned: {'; '.join(said)})" if said else ""
    if "scales" in row:     # auto rescaled the cell (per coordinate pair where one scale could not serve)
        widest = f"; a column {row['widest']:.2g}x off unit size" if row.get("widest", 1) > WIDEST else ""
        warned = (" (rescaled per pair" if isinstance(row["scales"]["q"], list) else " (rescaled") + widest + ")" \
            + warned
    if "stop" in row:
        return f"stops: {row['stop']}{warned}"
    if nominal is None or "error" not in nominal:
        return f"{row['error']:.3g}{warned}"
    factor = row["error"] / max(nominal["error"], 1e-300)
    word = "works" if factor <= 2 and row["error"] < NO_FIT else "degrades"
    return f"{word} {row['error']:.3g} ({factor:.2g}x){warned}"


def _fit_row(kind: str, scene: str, cell: str, budget: dict, seed: int) -> dict:
    """One grid cell's row, its seconds included (a worker's task)."""
    tic = time.perf_counter()
    row = fit(kind, scene, cell, budget, seed)[1]
    return {**row, "seconds": time.perf_counter() - tic}


def _rollout_rows(kind: str, budget: dict, horizon: int, seed: int) -> list[dict]:
    """The spring's nominal ``kind`` (trained again: a fit is deterministic at one thread) rolled out
    over ``horizon`` and 1000 steps and at omega dt 0.1, 2.5, 3.0 (a worker's task)."""
    model = fit(kind, "spring", "nominal", budget, seed)[0]
    short = energy_change(model, kind, 1000, 0.1, seed)
    rows = [{"kind": kind, "cell": "horizon 1,000 steps (nominal)", **short},
            {"kind": kind, "cell": f"horizon {horizon:,} steps", "nominal": short,
             **energy_change(model, kind, horizon, 0.1, seed)}]
    base = energy_change(model, kind, 100, 0.1, seed)
    rows.append({"kind": kind, "cell": "omega dt 0.1 (nominal)", **base})
    for wdt in (2.5, 3.0):
        rows.append({"kind": kind, "cell": f"omega dt {wdt}", "nominal": base, **energy_change(model, kind, 100, wdt, seed)})
    return rows


def _describe(task: tuple) -> str:
    function, arguments = task
    if function is _fit_row:
        return " ".join(map(str, arguments[:3]))
    if function is heavy:
        return f"heavy mass, seed {arguments[1]}"
    return f"{arguments[0]} rollouts" if function is _rollout_rows else "precision"


# a plan's measurement of a fit: this many steps of each kind's nominal fit on each scene, and a rollout of this many
# steps of the spring's (their cost per step times the grid's steps, horizons and precision fits)
PLAN_STEPS, PLAN_ROLLOUT = 60, 2000


def plan_stages(quick: bool, seed: int = 0, jobs: int = 1) -> list:
    """The grid's stages for a plan (``analysis/plan.py``), each estimated from short fits and a rollout of
    every kind measured now, on one thread: the fits, the rollouts (1000 steps and the horizon), the heavy
    mass, the precision part; the fits and rollouts shared over ``jobs`` workers."""
    budget, horizon = (QUICK, QUICK_HORIZON) if quick else (BUDGET, HORIZON)
    kinds = ("hnn", "mechanical") if quick else KINDS
    fit_seconds, roll_seconds = {}, {}

    def timed_fit(kind, scene, steps):
        tic = time.perf_counter()
        model = fit(kind, scene, "nominal", {**budget, "steps": steps}, seed)[0]
        return model, time.perf_counter() - tic
    with torch_threads(1), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for scene in SCENES:
            for kind in kinds:
                if not applies(kind, scene):
                    continue
                # the data, the model and a first step (twice: the first call of a kind pays its one-time costs),
                # then PLAN_STEPS more: a fit's cost is the setup and its steps at that pace
                setup = min(timed_fit(kind, scene, 0)[1] for _ in range(2))
                model, seconds = timed_fit(kind, scene, PLAN_STEPS)
                fit_seconds[kind, scene] = setup + max(seconds - setup, 0.0) * budget["steps"] / PLAN_STEPS
                if scene == "spring":
                    tic = time.perf_counter()
                    energy_change(model, kind, PLAN_ROLLOUT, 0.1, seed)
                    # the task trains the model again, then rolls it out over 1000, the horizon and 4 x 100 steps
                    roll_seconds[kind] = fit_seconds[kind, scene] + (time.perf_counter() - tic) * (
                        1400 + horizon) / PLAN_ROLLOUT
    fits = [fit_seconds[kind, scene] for scene in SCENES for kind in kinds if applies(kind, scene)
            for cell in SCENE_CELLS.get(scene, GRID_CELLS) if not quick or cell in QUICK_CELLS]
    # a heavy-mass task: the mechanical kind and the HNN, each twice (auto and off), about a spring fit each
    heavies = [2 * (fit_seconds.get(("mechanical", "spring"), 0.0) + fit_seconds[("hnn", "spring")])
               for _ in (HEAVY_SEEDS[:1] if quick else HEAVY_SEEDS)]
    tasks = fits + list(roll_seconds.values()) + heavies
    stages = [plan.Stage("fit", len(tasks), f"cells x kinds x scenes, {budget['steps']} steps each, and the heavy mass",
                         plan.schedule(tasks, jobs), f"{PLAN_STEPS} steps and a {PLAN_ROLLOUT}-step rollout of each "
                         f"kind timed now, with the kinds' rollouts, on {jobs} worker{'s' if jobs > 1 else ''}")]
    if not quick:       # one worker's task: 12 spring fits of the HNN, float32 and float64, 1 and 2 threads
        stages.append(plan.Stage("precision", 4 * len(PRECISION_SEEDS), "fits", 4 * len(PRECISION_SEEDS)
                                 * fit_seconds["hnn", "spring"], "the HNN's spring fit timed now"))
    return stages


def run(quick: bool, seed: int = 0, jobs: int = 1) -> dict:
    """The grid, the rollouts, the heavy mass and (unless ``quick``) the precision part, here (``jobs`` 1) or in
    ``jobs`` worker processes, the longest tasks first (the 10^5-step rollouts of the mechanical kind and the LNN
    are the longest). Each task seeds its own fit, so the numbers do not depend on ``jobs``."""
    budget, horizon = (QUICK, QUICK_HORIZON) if quick else (BUDGET, HORIZON)
    kinds = ("hnn", "mechanical") if quick else KINDS
    fits = [(_fit_row, (kind, scene, cell, budget, seed)) for scene in SCENES for kind in kinds if applies(kind, scene)
            for cell in SCENE_CELLS.get(scene, GRID_CELLS) if not quick or cell in QUICK_CELLS]
    slow = ("lagrangian", "mechanical")
    rollouts = [(_rollout_rows, (kind, budget, horizon, seed)) for kind in sorted(kinds, key=lambda k: k not in slow)]
    heavies = [(heavy, (budget, s)) for s in (HEAVY_SEEDS[:1] if quick else HEAVY_SEEDS)]
    tasks = rollouts + ([] if quick else [(precision, (budget,))]) + heavies + fits
    results = run_tasks(tasks, jobs, _describe)
    rolled = sorted((row for rows in results[:len(rollouts)] for row in rows), key=lambda row: kinds.index(row["kind"]))
    first_heavy = len(tasks) - len(fits) - len(heavies)
    return {"rows": results[-len(fits):], "rollouts": rolled, "heavy": [row for rows in results[first_heavy:first_heavy
                                                                                          + len(heavies)] for row in rows],
            "budget": budget, "horizon": horizon, "seed": seed, "precision": [] if quick else results[len(rollouts)]}


# the heavy mass: one degree of freedom whose dp/dt is 500x its dq/dt (m = k = 500, omega 1)
HEAVY = 500.0


def _heavy_spring(rows: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(rows, generator=g, dtype=torch.float64)
    p = HEAVY * torch.randn(rows, generator=g, dtype=torch.float64)
    return torch.stack([q, p], 1), torch.stack([p / HEAVY, -HEAVY * q], 1)


def heavy(budget: dict, seed: int) -> list[dict]:
    """The mechanical kind and the paper's HNN on the heavy mass (``HEAVY``), fit by ``hnn.train`` at its
    defaults (in ``Rescaled``: auto rescales p of RMS 500) and in the data's units (``units='off'``, the
    balanced loss alone): their field error, M^-1's relative RMS error over the test states (mechanical),
    and the rollout error (RK4 at dt 2 pi / 100 over three periods from 8 test starts, the distance to the
    exact path over q's and p's RMS, mean over starts and times)."""
    x, dxdt = _heavy_spring(budget["rows"], seed)
    test, test_dxdt = _heavy_spring(budget["rows"], seed + 1)
    out = []
    for kind in ("mechanical", "hnn"):
        for units in ("auto", "off"):
            torch.manual_seed(seed)
            model = hnn.kinds.model_from_args({"kind": kind, "input_dim": 2, "hidden_dim": budget["hidden"]})
            model = hnn.units.Rescaled(model) if units == "auto" else model
            row = {"kind": kind, "units": units, "seed": seed}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")     # units='off' warns: the point of that run
                hnn.train(model, x.float(), dxdt.float(), total_steps=budget["steps"], learn_rate=budget["learn_rate"],
                          seed=seed, progress=False, units=units)
            model = model.double()
            with torch.no_grad():
                row["field_error"] = field_error(model.time_derivative(test), test_dxdt)
                if kind == "mechanical":
                    learned = model.inverse_mass(test[:, :1])[:, 0, 0]
                    row["inverse_mass_error"] = float(((learned * HEAVY - 1) ** 2).mean().sqrt())
            t = np.linspace(0, 6 * math.pi, 301)
            tt = torch.as_tensor(t)[None]
            x0 = test[:8]
            q = x0[:, :1] * torch.cos(tt) + x0[:, 1:] / HEAVY * torch.sin(tt)
            exact = torch.stack([q, HEAVY * (-x0[:, :1] * torch.sin(tt) + x0[:, 1:] / HEAVY * torch.cos(tt))], -1)
            try:
                with torch.no_grad():
                    path = hnn.rollout(model.time_derivative, x0, t, method="rk4")
                size = torch.tensor([1.0, HEAVY], dtype=torch.float64)
                row["rollout_error"] = float(((path - exact) / size).norm(dim=-1).mean())
            except hnn.DivergenceError as err:
                row["rollout_stop"] = f"DivergenceError: {str(err)[:120]}"
            out.append(row)
    return out


# the scan of sizes: the unit spring with its states (q, p and their rates) times a, or its rates alone times b
# (a faster clock), fit in the data's own units; auto rescales those outside its bounds (hnn.units.AUTO_FAR)
SCAN_STATES = (0.03, 0.1, 0.3, 1, 3, 10, 30)
SCAN_RATES = (0.003, 0.01, 0.03, 0.1, 10, 30, 100, 300)
SCAN_KINDS = ("hnn", "mechanical")
SCAN_SEEDS = (0, 1, 2)


def scan_cells() -> list[tuple[float, float]]:
    """``(a, b)`` of the scan: states times a (rates with them), then rates alone times b."""
    return [(a, 1) for a in SCAN_STATES] + [(1, b) for b in SCAN_RATES]


def scan_row(kind: str, a: float, b: float, budget: dict, seed: int) -> dict:
    """``kind`` fit by ``hnn.train`` in the data's own units (``units='off'``) to the spring whose states read a
    times theirs and whose clock runs b times faster (dx/dt times a b; Hamilton's equations hold for H a^2 b):
    its field error on held-out states, and whether ``--units auto`` would rescale these data. A worker's task."""
    data = {split: _in_units(_spring(budget["rows"], seed + offset, 1.0), a, a, 1 / b)
            for split, offset in (("train", 0), ("test", 1))}
    torch.manual_seed(seed)
    model = hnn.kinds.model_from_args({"kind": kind, "input_dim": 2, "hidden_dim": budget["hidden"]})
    x, y = data["train"]["x"].float(), data["train"]["dxdt"].float()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hnn.train(model, x, y, total_steps=budget["steps"], learn_rate=budget["learn_rate"], seed=seed, progress=False,
                  units="off")
    with torch.no_grad():
        pred = model.time_derivative(data["test"]["x"].float()).double()
    return {"kind": kind, "a": a, "b": b, "seed": seed, "error": field_error(pred, data["test"]["dxdt"]),
            "auto_rescales": hnn.units.rescale_reason(x, y) is not None}


def scan(budget: dict, jobs: int) -> list[dict]:
    """Every scan cell of every ``SCAN_KINDS`` kind at each of ``SCAN_SEEDS``."""
    tasks = [(scan_row, (kind, a, b, budget, seed)) for kind in SCAN_KINDS for a, b in scan_cells()
             for seed in SCAN_SEEDS]
    return run_tasks(tasks, jobs, lambda task: f"scan {task[1][0]} states x{task[1][1]:g} rates x{task[1][2]:g} "
                                               f"seed {task[1][4]}")


def precision(budget: dict) -> list[dict]:
    """The HNN on the spring at each of ``PRECISION_SEEDS``, float32 and float64, on 1 and 2 torch threads."""
    out = []
    for wide in (False, True):
        for threads in (1, 2):
            with torch_threads(threads):
                for seed in PRECISION_SEEDS:
                    _, row = fit("hnn", "spring", "float64" if wide else "nominal", budget, seed)
                    out.append({"dtype": "float64" if wide else "float32", "threads": threads, "seed": seed, **row})
    return out
