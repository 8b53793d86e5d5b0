"""The bodies study's machinery (``analysis/bodies.py`` is its command): the pair kind fitted on a scene of 8 bodies
(``SCENES``: the chain of springs of experiment-lattice, the softened gravity of experiment-gravity, or the
Lennard-Jones cluster of experiment-lj cut off at 2.5), the same
model rolled out on the scene at N bodies beside the true forces' leapfrog, and the tables of docs/bodies.md. See
the command's docstring for the metrics."""
from __future__ import annotations

import functools
import statistics
import time

import numpy as np
import torch

import hnn
from hnn.interface import SplitField
from hnn.models.pair import TooManyPairsError, find_pairs, inside_cutoff, separations
from hnn.models.pair_table import TabulatedPair
from hnn.sweeps import backends
from hnn.threads import torch_threads
from hnn_analysis import pages
from hnn_analysis.provenance import machine

FULL_SIZES = (8, 64, 512, 4096)
QUICK_SIZES = (8, 32, 128, 256)
# scene (its task) -> its bodies in the page's sentence, its section of docs/bodies.md and its rollouts' defaults;
# every scene's task declares the same functions of any N: dynamics, hamiltonian, potential_gradient, random_config.
# Gravity's pulls reach every body, so a step at N = 4096 costs N^2 pairs (seconds), and its bodies speed up with N
# (the disk keeps its density): a shorter horizon at a finer step than the chain's, and its reference yoshida4 on
# the true forces at a quarter of the step (error ~ 4^-4 of a yoshida4 step's: the true leapfrog's rollout error
# against it moves by 1e-3 of itself from a reference at an eighth, by 1e-2 at a half, N = 8 and 512; DOP853 at
# rtol 1e-10 took thousands of calls at N = 512, hours at 4096) where the chain's is DOP853.
# Gravity's sizes reach 4096 for the true forces and the radial library (its softened term alone: 2.6 s a call of 2
# states against the true forces' 0.9 s, one thread, loaded 2-core box), 600 reference calls there being most of
# the study's time; 2 starts keep the whole of it within about 20 minutes on that box. The sampled and Adam fits stop
# at 512 by default (``largest``), by a row: their field calls at 4096 fit in memory (blocks and chunks) but take a
# minute (64 tanh neurons over 17 million pair rows) and minutes (Adam's V: 11 s a call at N = 1024), so a rollout
# would take an hour; ``--sizes`` runs every fit at every size asked
SCENES = {"lattice": {"bodies": "a chain of {n} bodies joined by springs", "section": "bodies",
                      "dt": 0.05, "horizon": 10.0, "starts": 4, "reference_divisions": None, "sizes": FULL_SIZES},
          "gravity": {"bodies": "{n} bodies under softened gravity (a rotating disk)", "section": "bodies-gravity",
                      "dt": 0.01, "horizon": 0.5, "starts": 2, "reference_divisions": 4, "sizes": FULL_SIZES,
                      "largest": {"swim": 512, "adam": 512, "swim+table": 512, "adam+table": 512},
                      "largest_why": "its field call there takes a minute or more on one thread (a table's too: 90% "
                                     "of the pairs lie past its range, where it reads the network; --sizes runs it)"},
          # the cluster cut off at r_c = 2.5 (``settings``: the task's own settings, given to its config and to its true
          # functions alike), so a step is O(N) by a cell list: every fit runs to N = 4096. The task's start law fills
          # a patch of its triangular lattice at one spacing whatever N, so a cluster of 4096 has the training's
          # density. A field call at N = 4096 of 2 states takes 57 ms (true forces), 63 (library), 210 (64 sampled
          # neurons) and 340 (Adam's V) on one thread of the loaded 2-core box; the reference, yoshida4 at a quarter
          # of the step (DOP853 would stop at every crossing of r_c, where the force jumps), takes 2400 of the true
          # forces' calls over a horizon of 2, most of the 2.1 minutes that N = 4096's reference, true forces and
          # library took on the quiet box; N = 8 ... 512 with every fit took 80 s (Adam's 2000 steps 34 s of it): the
          # whole study about 6 minutes quiet, 8 loaded. The horizon 2 (200 steps) lets the cut pairs cross r_c many
          # times in a rollout; 2 starts keep the study within 10 minutes
          "lj": {"bodies": "a Lennard-Jones cluster of {n} bodies", "section": "bodies-lj", "dt": 0.01,
                 "horizon": 2.0, "starts": 2, "reference_divisions": 4, "sizes": FULL_SIZES,
                 "settings": {"cutoff": 2.5}}}
FITS = ("library", "swim", "adam", "swim+table", "adam+table")
QUICK_FITS = ("library", "swim", "swim+table")
# a fit "X+table" is fit X's model with its V(r) tabulated (hnn.models.pair_table.TabulatedPair): no fit of its own.
# Its range: the fitted distances' closest pair to TABLE_REACH times their farthest, a pair outside it reading the
# network itself. Not farther: past the fitted distances sampled tanh neurons saturate, V' tends to 0 there, and a
# table mostly of that tail would hold its slope error to the tail's tiny median slope (hnn.models.pair_table). Its
# slope error TABLE_TOL: a sampled fit's own V' rounds at 3e-7 (Lennard-Jones) to 2e-6 (gravity) of its size, its
# coefficients large and cancelling, and no table follows it closer (seed 0); 1e-5 is far below the fits' own
# errors against the true forces (1e-4 and up)
TABLE_REACH = 2.0
TABLE_TOL = 1e-5
REPEATS = 5             # timed rollouts per N (the median counts)
TIMED_STEPS = 20        # leapfrog steps of each timed rollout
# seconds the timed rollouts of one field at one N may take: past it (a step of seconds: gravity at N = 4096) the
# step's time is the measured rollout's own, all its steps timed once (marked in the table); every lattice step
# (0.1 s at most) is timed by the median of REPEATS
TIMING_BUDGET = 30.0
REFERENCE_RTOL = 1e-10
# states of a path whose true H is taken in one call: the cluster's cell list over a whole path at N = 4096 (402
# states) held 4.5 GB at once, 32 states 0.4 GB, in about the same time
ENERGY_ROWS = 32


def _settings(scene: str) -> dict:
    """The task settings a scene runs at (its ``settings``: the lj cluster's cutoff), none where it declares none."""
    return dict(SCENES[scene].get("settings", {}))


def _fit(scene: str, fit: str, data: dict, seed: int, adam_steps: int, hidden: int):
    """``(model, seconds, what, args)`` of the pair kind fitted on the ``scene`` task's data by ``fit`` (float64);
    ``args`` rebuild it (``hnn.kinds.model_from_args``, then its ``state_dict``), as a saved run's do."""
    config = hnn.tasks.task_config(scene, {"seed": seed, **_settings(scene)})
    args = {**config.to_dict(), "kind": "pairwise", "fit": fit, "hidden_dim": hidden, "dtype": "float64"}
    torch.manual_seed(seed)
    model = hnn.kinds.model_from_args(args)
    x, dxdt = (torch.tensor(data[k], dtype=torch.float64) for k in ("x", "dxdt"))
    with torch_threads(1):
        if fit == "adam":
            stats = hnn.train(model, x, dxdt, total_steps=adam_steps, batch_size=200, seed=seed, weight_decay=0.0,
                              balance="off", units="off", progress=False)
            return (model.eval(), stats["seconds"],
                    f"{adam_steps + 1} Adam steps, final loss {stats['train_loss'][-1]:.2e}", args)
        stats = hnn.fits.solve(model, x, dxdt, fit=fit, seed=seed, progress=False)
    what = stats["fit"].get("equation") or f"{hidden} sampled radial neurons"
    return model.eval(), stats["seconds"], f"{what}; train loss {stats['train_loss'][0]:.2e}", args


class _Truth:
    """A scene task's true functions of any N at the scene's settings: ``dynamics``, ``hamiltonian``,
    ``potential_gradient`` (each the task's, given ``settings``), and the task's ``random_config``."""

    def __init__(self, data_module, settings: dict):
        self.dynamics, self.hamiltonian, self.potential_gradient = (
            functools.partial(getattr(data_module, name), **settings)
            for name in ("dynamics", "hamiltonian", "potential_gradient"))
        self.random_config = data_module.random_config
        self.layout = functools.partial(data_module.layout, **settings)
        # a model's path that leaves where it was fitted: diverged (hnn.DivergenceError), or into the scene's wall
        # (the Lennard-Jones task's WallError, from its H); each a row that says so
        wall = getattr(data_module, "WallError", None)
        self.left = (hnn.DivergenceError,) + ((wall,) if wall else ())


def _true_field(truth: _Truth) -> SplitField:
    """The scene's true field, split as a leapfrog reads it (dT/dp = p: unit masses; dV/dq the task's)."""
    return SplitField(truth.dynamics, lambda p: p, truth.potential_gradient)


def _rollout(field, x0: torch.Tensor, t: np.ndarray, dt: float) -> tuple[torch.Tensor, float]:
    """The leapfrog path ``(starts, len(t), width)`` of ``field`` from ``x0``, and its seconds per step."""
    tic = time.perf_counter()
    with torch.no_grad():
        path = hnn.rollout(field, x0, t, method="leapfrog", dt=dt)
    return path, (time.perf_counter() - tic) / int(round((t[-1] - t[0]) / dt))


def _timed(field, x0: torch.Tensor, dt: float, measured: float) -> dict:
    """``seconds_per_step``: the median of ``REPEATS`` timed rollouts, or ``measured`` (the rollout's own, with
    ``timed: 'rollout'``) where those would pass ``TIMING_BUDGET``."""
    if measured * REPEATS * TIMED_STEPS > TIMING_BUDGET:
        return {"seconds_per_step": measured, "timed": "rollout"}
    return {"seconds_per_step": _seconds_per_step(field, x0, dt)}


def _seconds_per_step(field, x0: torch.Tensor, dt: float) -> float:
    t = np.arange(TIMED_STEPS + 1) * dt
    times = []
    with torch.no_grad():
        hnn.rollout(field, x0, t[:3], method="leapfrog", dt=dt)          # warm-up: first-call setup
        for _ in range(REPEATS):
            tic = time.perf_counter()
            hnn.rollout(field, x0, t, method="leapfrog", dt=dt)
            times.append(time.perf_counter() - tic)
    return statistics.median(times) / TIMED_STEPS


# bodies whose distances to every body one block of ``torch.cdist`` holds (gravity at N = 4096: 2 states x 256 x 4096)
DISTANCE_BLOCK = 256


def _distances(x: torch.Tensor, bodies) -> torch.Tensor:
    """The distances ``(pairs,)`` of the pairs that ``bodies`` interacts, over all states ``x`` ``(batch, width)``
    (every pair block by block of bodies; a cutoff's pairs closer than it)."""
    q, _ = bodies.split(x)
    if bodies.pairs != "all":
        i, j = find_pairs(q, bodies)
        _, r = separations(q, i, j)
        inside = inside_cutoff(r, bodies)
        return (r if inside is None else r[inside]).reshape(-1)
    count, parts = q.shape[1], []
    for start in range(0, count, DISTANCE_BLOCK):
        rows = torch.arange(start, min(start + DISTANCE_BLOCK, count))
        later = rows[:, None] < torch.arange(count)[None, :]        # each pair once, i < j
        parts.append(torch.cdist(q[:, rows], q)[:, later].reshape(-1))
    return torch.cat(parts)


def _reach(r: torch.Tensor, fitted: tuple[float, float]) -> dict:
    """The closest and farthest pair of ``r`` and the shares of its pairs outside the ``fitted`` distances."""
    return {"closest": float(r.min()), "farthest": float(r.max()), "below": float((r < fitted[0]).double().mean()),
            "beyond": float((r > fitted[1]).double().mean())}


def _errors(path: torch.Tensor, reference: torch.Tensor, energy, count: int) -> dict:
    """Energy error per body (max over t, mean over starts) and the rollout error at the horizon."""
    H = torch.cat([energy(rows) for rows in path.reshape(-1, path.shape[-1]).split(ENERGY_ROWS)]).reshape(path.shape[:2])
    per_body = ((H - H[:, :1]).abs().max(dim=1).values / count).mean()
    end, ref = path[:, -1], reference[:, -1]
    rollout = (torch.linalg.vector_norm(end - ref, dim=1) / torch.linalg.vector_norm(ref, dim=1)).mean()
    return {"energy_per_body": float(per_body), "rollout": float(rollout)}


def study(sizes, fits, seed: int, starts: int, dt: float, horizon: float, adam_steps: int, hidden: int,
          scene: str = "lattice", largest: dict | None = None, jobs: int = 1, backend: str = "local",
          address: str | None = None) -> dict:
    """The rows of every N of ``sizes`` for each of ``fits``; ``largest``: fit -> the largest N it is rolled out at
    (past it, a row saying so: the scene's ``largest_why``), None: every fit at every N. The fits run here; each N
    is a cell of its own (``_measure_size``), measured one after another (``jobs`` 1), in ``jobs`` worker
    processes, or as Ray tasks (``backend='ray'``, ``address``: a cluster), one thread each: the same rows but
    their seconds, which cells measured side by side share with each other."""
    largest = largest or {}
    if scene not in SCENES:
        raise ValueError(f"scene {scene!r}: choose one of {', '.join(SCENES)}")
    settings = _settings(scene)
    data_module = hnn.load_task(scene)
    data = hnn.tasks.task_config(scene, {"seed": seed, **settings}).dataset()
    # the distances the fits saw: their interacting pairs over every training state
    seen = _distances(torch.as_tensor(data["x"], dtype=torch.float64),
                      _Truth(data_module, settings).layout(data_module.NUM_BODIES))
    fitted_distances = (float(seen.min()), float(seen.max()))
    fitted, meta, models = {}, {}, {}
    for fit in fits:
        if fit.endswith("+table"):
            source = fit.removesuffix("+table")
            if source not in fits:
                raise ValueError(f"fit {fit!r} tabulates the {source} fit's model: study {source} too (--fits ... "
                                 f"{source} {fit})")
            continue
        model, seconds, what, args = _fit(scene, fit, data, seed, adam_steps, hidden)
        fitted[fit] = (args, {k: v.detach() if torch.is_tensor(v) else v for k, v in model.state_dict().items()})
        models[fit] = model
        print(f"fitted {fit} on N = {data_module.NUM_BODIES} in {seconds:.2f} s: {what}", flush=True)
        meta[fit] = {"seconds": seconds, "what": what}
    for fit in (f for f in fits if f.endswith("+table")):
        meta[fit] = _table_meta(models[fit.removesuffix("+table")], fitted_distances)
        print(f"{fit}: {meta[fit]['what']}", flush=True)
    common = {"scene": scene, "seed": seed, "starts": starts, "dt": dt, "horizon": horizon, "fits": list(fits),
              "largest": largest, "models": fitted, "fitted_distances": fitted_distances}
    # the largest N first: with several workers the longest cells start at once, and the last to finish is short
    cells = [{**common, "count": count} for count in sorted(sizes, reverse=True)]
    rows, tic = [], time.perf_counter()
    for done, (index, row) in enumerate(backends.map_cells(_measure_size, cells, jobs, backend, address), 1):
        if isinstance(row, BaseException):
            raise RuntimeError(f"N = {cells[index]['count']}: {type(row).__name__}: {row}") from row
        rows.append(row)
        print(f"[{done}/{len(cells)}, {time.perf_counter() - tic:.0f} s] {_row_line(row, fits)}", flush=True)
    rows.sort(key=lambda row: row["N"])
    return {"rows": rows, "fits": meta,
            "settings": {"scene": scene, "sizes": list(sizes), "fits": list(fits), "seed": seed, "starts": starts,
                         "dt": dt, "horizon": horizon, "adam_steps": adam_steps, "hidden_dim": hidden,
                         "trained_on": data_module.NUM_BODIES, "method": "leapfrog", "reference_rtol": REFERENCE_RTOL,
                         "reference_divisions": SCENES[scene]["reference_divisions"], "largest": largest,
                         "timing_budget": TIMING_BUDGET, "repeats": REPEATS, "timed_steps": TIMED_STEPS,
                         "threads": 1, "jobs": jobs, "backend": backend, "task_settings": settings,
                         "fitted_distances": list(fitted_distances)}}


def _table(model, fitted_distances) -> TabulatedPair:
    """``model``'s V tabulated over the fitted distances' closest pair to ``TABLE_REACH`` times their farthest."""
    lo, hi = fitted_distances
    return TabulatedPair(model, (lo, TABLE_REACH * hi), tol=TABLE_TOL)


def _table_meta(model, fitted_distances) -> dict:
    """How a fit's table was made (its seconds to build, knots, range and slope error), or why it was refused."""
    tic = time.perf_counter()
    try:
        made = _table(model, fitted_distances)
    except ValueError as err:
        return {"seconds": time.perf_counter() - tic, "what": f"refused: {err}"}
    lo, hi = made.r_range
    return {"seconds": time.perf_counter() - tic, "knots": made.knots, "max_error": made.max_error,
            "what": f"its V(r) as a table of {made.knots} knots over r = {lo:.3g} to {hi:.3g}, cubic in log r; "
                    f"slope error at most {made.max_error:.1e} of the network's (tol {TABLE_TOL:g})"}


def _measure_size(cell: dict) -> dict:
    """One N's row (``study``'s cell): the true forces' and each fit's energy and rollout errors against the
    reference, and their seconds per step; each fit rebuilt from its ``(args, state_dict)``."""
    scene, count, fits, largest = cell["scene"], cell["count"], cell["fits"], cell["largest"]
    scene_truth = _Truth(hnn.load_task(scene), _settings(scene))
    truth = _true_field(scene_truth)
    models = {}
    for fit, (args, state) in cell["models"].items():
        model = hnn.kinds.model_from_args(args)
        model.load_state_dict(state)
        models[fit] = model.eval()
    refused = {}                                # fit -> why its table was refused
    for fit in (f for f in fits if f.endswith("+table")):
        try:
            models[fit] = _table(models[fit.removesuffix("+table")], cell["fitted_distances"])
        except ValueError as err:
            refused[fit] = str(err)
    dt, divisions = cell["dt"], SCENES[scene]["reference_divisions"]
    t = np.linspace(0.0, cell["horizon"], int(round(cell["horizon"] / dt)) + 1)
    rng = np.random.RandomState(cell["seed"] + 1000)
    x0 = torch.tensor(np.stack([scene_truth.random_config(rng, count) for _ in range(cell["starts"])]))
    with torch.no_grad():
        if divisions:
            reference = hnn.rollout(truth, x0, t, method="yoshida4", dt=dt / divisions)
        else:
            reference = hnn.rollout(scene_truth.dynamics, x0, t, method="dop853", rtol=REFERENCE_RTOL,
                                    atol=REFERENCE_RTOL)
    true_path, measured = _rollout(truth, x0, t, dt)
    row = {"N": count, "true": {**_errors(true_path, reference, scene_truth.hamiltonian, count),
                                **_timed(truth, x0, dt, measured)},
           "starts": _reach(_distances(x0, scene_truth.layout(count)), cell["fitted_distances"])}
    for fit in fits:
        if count > largest.get(fit, count):     # past where the scene rolls this fit out: said by a row
            row[fit] = {"not_run": f"past N = {largest[fit]}: {SCENES[scene]['largest_why']}",
                        "seconds_per_step": None}
            continue
        if fit in refused:                      # a table its tolerance refused: the reason
            row[fit] = {"not_run": f"no table: {refused[fit]}", "seconds_per_step": None}
            continue
        try:
            path, measured = _rollout(models[fit].field, x0, t, dt)
            errors = _errors(path, reference, scene_truth.hamiltonian, count)
        except scene_truth.left as err:         # a model whose paths leave where it was fitted: said
            row[fit] = {"diverged": str(err).split(". ")[0],
                        "seconds_per_step": _seconds_per_step(models[fit].field, x0, dt)}
            continue
        except TooManyPairsError as err:        # more pairs than its field call may hold: what it needs
            row[fit] = {"diverged": f"too many pairs: {str(err).split(':')[0]}", "seconds_per_step": None}
            continue
        row[fit] = {**errors, **_timed(models[fit].field, x0, dt, measured)}
    return row


def _row_line(row: dict, fits) -> str:
    cells = [f"N={row['N']}", f"true: E/N {row['true']['energy_per_body']:.2e} "
                              f"err {row['true']['rollout']:.2e} {row['true']['seconds_per_step'] * 1e3:.3f} ms"]
    cells += [f"{fit}: " + (f"diverged ({row[fit]['diverged']})" if "diverged" in row[fit] else
                            f"not run ({row[fit]['not_run']})" if "not_run" in row[fit] else
                            f"E/N {row[fit]['energy_per_body']:.2e} err {row[fit]['rollout']:.2e}")
              + f" {_ms(row[fit]['seconds_per_step'])} ms" for fit in fits]
    return " | ".join(cells)


def _bodies(settings: dict, count: int) -> str:
    """``'a chain of 8 bodies joined by springs'``: the scene's bodies in the page's words (a study saved before
    scenes: the lattice)."""
    return SCENES[settings.get("scene", "lattice")]["bodies"].format(n=count)


def _task_settings(settings: dict) -> str:
    """``', task settings: cutoff 2.5'``: the task settings the scene ran at, where it declares any."""
    given = settings.get("task_settings") or {}
    return f", task settings: {', '.join(f'{name} {value:g}' for name, value in given.items())}" if given else ""


def _ms(seconds: float | None, timed: str | None = None) -> str:
    """Milliseconds of a step (``*``: timed by its one measured rollout, ``TIMING_BUDGET``), or ``n/a`` where none
    was timed (a field call past memory, a fit not run)."""
    return "n/a" if seconds is None else f"{seconds * 1e3:.3f}" + ("*" if timed == "rollout" else "")


def _share(value: float) -> str:
    """A share of pairs as a percentage; a few pairs of millions, which one decimal would print as 0.0%, as <0.1%."""
    return "<0.1%" if 0 < value < 0.0005 else f"{value:.1%}"


def _reference(settings: dict) -> str:
    if settings.get("reference_divisions"):
        return (f"yoshida4 on the true forces at dt = {settings['dt'] / settings['reference_divisions']:g}")
    return f"DOP853 at rtol {settings['reference_rtol']:g}"


def table(results: dict) -> str:
    """The page's section: how each fit was found, then one table per fit against N with the true forces beside."""
    meta, settings = results["meta"], results["settings"]
    jobs = settings.get("jobs", 1)
    side = "" if jobs == 1 and settings.get("backend", "local") == "local" else (
        f", the sizes measured {jobs} at a time" if settings.get("backend", "local") == "local" else
        ", each size a Ray task")
    lines = [pages.generated_by(meta, f"{machine(meta)}, torch {meta.get('torch', '?')}, one thread{side}") + ".", "",
             f"Fitted on {_bodies(settings, settings['trained_on'])} (seed {settings['seed']}{_task_settings(settings)}); "
             f"each N rolled out from "
             f"{settings['starts']} starts by leapfrog at dt = {settings['dt']:g} to t = {settings['horizon']:g}, "
             f"float64; reference {_reference(settings)}.", ""]
    for fit, how in results["fits"].items():
        made = "to tabulate" if fit.endswith("+table") else "to fit"
        lines.append(f"- `{fit}` ({how['seconds']:.2f} s {made}): {how['what']}")
    for fit in settings["fits"]:
        lines += ["", f"**{fit}**", "",
                  "| N | energy error / body | true forces' | rollout error | true forces' | ms / step | true forces' "
                  "| ratio |", "|---|---|---|---|---|---|---|---|"]
        for row in results["rows"]:
            mine, true = row[fit], row["true"]
            said = (f"diverged: {mine['diverged']}" if "diverged" in mine else
                    f"not run: {mine['not_run']}" if "not_run" in mine else None)
            errors = (f"{said} | {true['energy_per_body']:.2e} | | {true['rollout']:.2e}" if said else
                      f"{mine['energy_per_body']:.2e} | {true['energy_per_body']:.2e} | "
                      f"{mine['rollout']:.2e} | {true['rollout']:.2e}")
            ratio = "" if mine["seconds_per_step"] is None else f"{mine['seconds_per_step'] / true['seconds_per_step']:.1f}x"
            lines.append(f"| {row['N']} | {errors} | {_ms(mine['seconds_per_step'], mine.get('timed'))} | "
                         f"{_ms(true['seconds_per_step'], true.get('timed'))} | {ratio} |")
    if all("starts" in row for row in results["rows"]):
        lo, hi = settings["fitted_distances"]
        lines += ["", f"**Distances at the starts** against the fits' ({lo:.3g} to {hi:.3g}: every interacting pair of "
                      "the training states): a fit reads a pair outside them by extrapolation, and a path that "
                      "diverges at some N had many there", "",
                  "| N | closest pair | farthest pair | pairs closer than fitted | pairs farther than fitted |",
                  "|---|---|---|---|---|"]
        lines += [f"| {row['N']} | {row['starts']['closest']:.3g} | {row['starts']['farthest']:.3g} | "
                  f"{_share(row['starts']['below'])} | {_share(row['starts']['beyond'])} |" for row in results["rows"]]
    if any(cell.get("timed") == "rollout" for row in results["rows"] for cell in row.values()
           if isinstance(cell, dict) and "seconds_per_step" in cell):
        lines += ["", f"\\* timed by the rollout measured above, all its steps once: {settings['repeats']} timed "
                      f"rollouts of {settings['timed_steps']} steps would pass {settings['timing_budget']:g} s"]
    return "\n".join(lines) + "\n"
