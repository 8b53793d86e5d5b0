"""The scene study's stages as a library: what it trains (each scene's kinds at the default cell, the
grid of width x training fraction, the D-HNN split), what it measures (``measure_units``, shared out by
``scene_measure``), the scene cards (``scene_card``), and ``run``, which does them in that order.
``analysis/scene_study.py`` is its command; ``scene_report`` writes what ``run`` returns.
"""
from __future__ import annotations

import dataclasses
import math
import statistics
import time
from pathlib import Path


import hnn
from hnn.threads import torch_threads
from hnn_analysis import plan
from hnn_analysis.paper import study
from hnn_analysis.provenance import provenance
from hnn_analysis.scenes import scene_common, scene_measure, scene_metrics as sm, scene_rungs
from hnn_analysis.scenes.scene_common import CARD_FACTOR, Scene, scene_settings, task_rungs, train

WIDTHS, FRACTIONS = (16, 32, 64, 128, 200), (0.1, 0.25, 0.5, 1.0)
# --quick: a grid of one narrow cell beside the default one, fewer steps than reproduce.py --quick, and
# the speed study of the paper's HNN alone (each cut is printed: quick_cuts)
QUICK_WIDTHS, QUICK_FRACTIONS = (16,), (0.25,)
QUICK_STEPS = 60
QUICK_SPEED_KINDS = ("hnn",)
# --quick: the speed study of the first QUICK_SPEED_STUDIES scenes (the scenes' order) that have a speed ladder
QUICK_SPEED_STUDIES = 1
# --quick: the kinds trained by Adam (the paper's pair) and those on the grid; the fits' rungs over them
# (scene_rungs.RUNGS, GRID_RUNGS) stay
QUICK_KINDS = ("baseline", "hnn")
QUICK_GRID_KINDS = ("hnn",)
# --quick: a scene whose dataset takes longer than this to build (its TaskSpec.data_cost, on the reference box) is
# left out unless --scenes names it (the pixels' frames: 20 s of the 90 s)
QUICK_DATA_SECONDS = 5.0
DEFAULT_CELL = (200, 1.0)
# --quick: at most this many training rows a fit (scene_rungs.capped): a library's solve grows with its rows,
# and the 3-body's 100000 took 90 s on a quiet 2-core box (2-body: 78 s on a loaded one)
QUICK_FIT_ROWS = 500
# --quick: each stage's share of its budget (commands.QUICK_BUDGETS["scene_study"]), in seconds: the plan says a
# stage whose estimate passes its share; the rest of the budget is the start, the plan, the datasets, the cards
QUICK_SHARES = {"train": 35.0, "data": 10.0, "measure": 40.0}


DHNN_FIELDS = {"split": "dhnn", "learn_rate": 5e-3, "total_steps": 5000, "batch_size": 128, "weight_decay": 0.0,
               "name": "real-dhnn"}
DHNN_MODELS = ("baseline", "hnn", "dissipative")


# ----------------------------------------------------------------------------------------------
# what to train


def _cell_fields(width: int, fraction: float, task: str) -> dict:
    if (width, fraction) == DEFAULT_CELL:
        return {}       # the defaults: reproduce.py's own runs
    return {"hidden_dim": width, "train_fraction": fraction, "name": f"{task}-w{width}-f{fraction:g}"}


def _row(task: str, cell: tuple, quick: bool, extra=None, name: str | None = None) -> dict:
    width, fraction = cell
    spec = hnn.task_spec(task)
    fields = {**spec.settings, **(spec.quick if quick else {}), **_cell_fields(width, fraction, task), **(extra or {})}
    return {"row": name or f"{task}@{width}x{fraction:g}", "task": task, "fields": fields, "note": None, "cell": cell,
            **({"fit_rows": QUICK_FIT_ROWS} if quick else {})}


def plan_rows(scenes, quick: bool) -> list[dict]:
    """Every (task, cell) row of the study: the default cell of every scene, the grid of the grid scenes."""
    widths, fractions = (QUICK_WIDTHS, QUICK_FRACTIONS) if quick else (WIDTHS, FRACTIONS)
    rows = [_row(task, DEFAULT_CELL, quick) for task in scenes]
    for task in scenes:
        if scene_settings(task).get("grid"):
            rows += [_row(task, (w, f), quick) for w in widths for f in fractions if (w, f) != DEFAULT_CELL]
    return rows


def quick_scenes(scenes: list[str]) -> list[str]:
    """The scenes a quick study takes of ``scenes`` when none is named: those whose dataset builds within
    ``QUICK_DATA_SECONDS`` on the reference box (``TaskSpec.data_cost``)."""
    return [task for task in scenes if hnn.task_spec(task).data_cost <= QUICK_DATA_SECONDS]


def rungs_of(quick: bool) -> tuple[tuple, tuple]:
    """``(the rungs at the default cell, the rungs on the grid)``: every studied kind and the fits' rungs over
    them, or a quick study's ``QUICK_KINDS`` and ``QUICK_GRID_KINDS`` and theirs."""
    kinds, grid_kinds = (QUICK_KINDS, QUICK_GRID_KINDS) if quick else (scene_common.kinds(),) * 2
    return tuple(kinds + tuple(scene_rungs.fit_rungs(kinds, scene_rungs.RUNGS))), \
        tuple(grid_kinds + tuple(scene_rungs.fit_rungs(grid_kinds, scene_rungs.GRID_RUNGS)))


def speed_scenes(scenes) -> list[str] | None:
    """The scenes whose speed a quick study measures: the first ``QUICK_SPEED_STUDIES`` with a speed ladder."""
    return [task for task in scenes if "dts" in scene_settings(task)][:QUICK_SPEED_STUDIES]


def quick_cuts(studied: list[str], seeds: int, quick_seeds: int = 1, left_out=()) -> list[str]:
    """What ``--quick`` cuts from the full study of the scenes ``studied`` (``seeds``: the full
    study's ``--seeds``; ``quick_seeds``: the quick run's), one phrase each, as ``main`` prints them."""
    quick, full = scene_common.QUICK, scene_common.FULL
    drift = [task for task in speed_scenes(studied) if scene_settings(task).get("drift")]    # the speed study's
    cuts = study.quick_cuts(studied, QUICK_STEPS)
    rungs, grid_rungs = rungs_of(True)
    if left_out:
        cuts.append(f"scenes: {', '.join(left_out)} left out (a dataset over {QUICK_DATA_SECONDS:g} s to build on the "
                    "reference box: " + ", ".join(f"{t} {hnn.task_spec(t).data_cost:g} s" for t in left_out)
                    + "; --scenes names one to study it)")
    cuts += [f"kinds: {', '.join(rungs)} of every kind and rung; on the grid {', '.join(grid_rungs)}",
             f"fits: at most {QUICK_FIT_ROWS} training rows each (a cell's fraction of them where that is fewer); "
             "a fit's training cost is the solve its run recorded, not solved again",
             f"grid: widths {', '.join(map(str, QUICK_WIDTHS))} x fractions {', '.join(map(str, QUICK_FRACTIONS))} "
             f"of {', '.join(map(str, WIDTHS))} x {', '.join(map(str, FRACTIONS))}",
             *([f"1 seed of {seeds}, the grid's as the default cell's, so the cards test nothing on seeds"]
               if quick_seeds == 1 else [f"{quick_seeds} seeds of {seeds}"] if quick_seeds < seeds else []),
             f"rollout metrics: {quick['starts']} starts of {full['starts']}, over {quick['horizon']} training "
             f"lengths of {full['horizon']}, {quick['points']} points per length of {full['points']}",
             f"speed at accuracy: the {', '.join(QUICK_SPEED_KINDS)} kind only of every kind, of the first "
             f"{QUICK_SPEED_STUDIES} scene(s) with a speed ladder ({', '.join(speed_scenes(studied)) or 'none here'}), the "
             f"{sm.QUICK_DTS} coarsest of every other step size, tolerances "
             f"{', '.join(f'{r:g}' for r in sm.QUICK_RTOLS)} of {', '.join(f'{r:g}' for r in sm.RTOLS)}, each "
             f"setting timed {quick['timings']} time(s) of {full['timings']}"]
    if drift:
        cuts.append(f"energy drift: {quick['drift_periods']} periods of " + ", ".join(
            f"{scene_settings(task)['periods']} ({task})" for task in drift)
            + f", at most {quick['drift_budget']:g} s a setting of {full['drift_budget']:g}")
    cuts.append(f"rollouts of the models: at most {scene_measure.QUICK_ROLLOUT_SECONDS:g} s each on the reference "
                f"box, {scene_measure.QUICK_ROLLOUT_CALLS} field calls (an energy protocol's, a rollout error's); one "
                "stiff along its path stops there, the same on every box, and says so")
    return cuts


# ----------------------------------------------------------------------------------------------
# scene cards


def _key_metric(m: dict) -> tuple[float | None, float | None]:
    """(energy MSE of the scene's main protocol, rollout error) of one measured model."""
    energy = m.get("energy_mse_corrected") or m.get("energy_mse_paper")
    return (energy[0] if energy else None), (m["rollout"]["error"] if "rollout" in m else None)


def scene_card(cells: dict) -> dict | None:
    """The smallest model (parameters, then data fraction, then training cost: the median of its seeds'
    ``scene_measure.cost_seconds``) whose mean over seeds comes within ``CARD_FACTOR`` of the scene's
    best mean energy MSE and best mean rollout error. ``cells`` is ``{(kind, width, fraction): {seed:
    measured}}``. Where no model is within ``CARD_FACTOR`` of both (the two bests come from different
    models), the model nearest both: the smallest larger of its two ratios. ``within`` is the pick's
    larger ratio to the bests (at most ``CARD_FACTOR`` unless it fell back).

    With several seeds the card also says what they cannot settle: ``unsettled`` names the smaller
    models (cells) whose mean is not within ``CARD_FACTOR`` of both bests but whose lowest seed on
    each error is (the seeds cannot separate them from the pick), and ``pick_straddles`` whether the
    pick's highest seed on either error is over it; both are None with one seed, where nothing is tested.
    ``cells``' kinds may be a fit's rungs (``scene_rungs``: ``hnn+swim``); ``cheapest`` and ``libraries``
    name the model enough that trains fastest and the libraries enough (``_cheapest_and_libraries``)."""
    spread = {}
    for key, per_seed in cells.items():
        pairs = [_key_metric(m) for m in per_seed.values()]
        spread[key] = (scene_common.seed_spread([e for e, _ in pairs]), scene_common.seed_spread([r for _, r in pairs]))
    spread = {k: v for k, v in spread.items() if v != (None, None)}
    if not spread:
        return None
    best_e = min((e[0] for e, _ in spread.values() if e is not None), default=None)
    best_r = min((r[0] for _, r in spread.values() if r is not None), default=None)

    def ratio(key, at: int) -> float:
        """The larger ratio to the bests, of the seeds' mean (at 0), lowest (1) or highest (2)."""
        ratios = [(value[at] / best if best > 0 else 1.0) if value is not None else math.inf
                  for value, best in zip(spread[key], (best_e, best_r)) if best is not None]
        return max(ratios, default=1.0)

    ok = [k for k in spread if ratio(k, 0) <= CARD_FACTOR]

    def size(key) -> tuple:
        # fewest parameters, then the least data (both exact), then the fastest to train: the median of
        # its seeds' timings, which move between sittings, so it decides only between models equal on both
        m = next(iter(cells[key].values()))
        return m["params"], key[2], scene_measure.median_cost_seconds(cells[key]) or 0.0

    pick = min(ok, key=size) if ok else min(spread, key=lambda k: (ratio(k, 0), *size(k)))
    # ``cheapest`` and ``libraries`` (_cheapest_and_libraries): the model enough that trains fastest, and the
    # libraries enough, with the equations they found
    if not math.isfinite(ratio(pick, 0)):
        return None
    seeds = len(cells[pick])
    several = seeds > 1
    unsettled = ([f"{k[0]}, width {k[1]}, {k[2]:g} of the data" for k in sorted(spread, key=size)
                  if size(k) < size(pick) and k not in ok and len(cells[k]) > 1 and ratio(k, 1) <= CARD_FACTOR]
                 if several and pick in ok else None)
    m = next(iter(cells[pick].values()))
    return {**_cheapest_and_libraries(cells, ok, spread),
            "cheapest_rollout": cheapest_rollout({k: cells[k] for k in ok}, {k: spread[k] for k in ok}),
            "kind": pick[0], "width": pick[1], "fraction": pick[2], "best_energy": best_e, "best_rollout": best_r,
            "params": m["params"], "train_seconds": scene_measure.median_cost_seconds(cells[pick]), "n_seeds": seeds,
            "energy": spread[pick][0][0] if spread[pick][0] else None,
            "rollout": spread[pick][1][0] if spread[pick][1] else None, "within": ratio(pick, 0),
            "unsettled": unsettled, "pick_straddles": (ratio(pick, 2) > CARD_FACTOR) if several and pick in ok else None}


def _cheapest_and_libraries(cells: dict, ok: list, spread: dict) -> dict:
    """Beside a card's pick: ``cheapest``, the model enough (within ``CARD_FACTOR`` of both bests on its seeds'
    mean) that trains in the fewest seconds (the median of its seeds' ``scene_measure.cost_seconds``), and
    ``libraries``, the rungs among those enough whose model is a sum of written-out terms (``hnn+library``,
    ``baseline+sindy``: they found the scene's equations), each with the equation its first seed printed."""
    def seconds(key) -> float:
        return scene_measure.median_cost_seconds(cells[key]) or math.inf

    out = {"cheapest": None, "libraries": []}
    if ok:
        key = min(ok, key=lambda k: (seconds(k), k[1], -k[2]))
        out["cheapest"] = {"kind": key[0], "width": key[1], "fraction": key[2], "train_seconds": seconds(key),
                           "energy": spread[key][0][0] if spread[key][0] else None,
                           "rollout": spread[key][1][0] if spread[key][1] else None}
    for key in sorted(ok, key=seconds):
        if scene_rungs.is_library(key[0]):
            first = cells[key][min(cells[key])]
            out["libraries"].append({"kind": key[0], "fraction": key[2], "train_seconds": seconds(key),
                                     "equation": first.get("equation")})
    return out


def cheapest_rollout(cells: dict, spread: dict) -> dict | None:
    """The model of ``cells`` (``{(kind, width, fraction): {seed: measured}}``, those whose means are within
    ``CARD_FACTOR`` of both bests: ``spread`` their ``seed_spread``s) whose rollout is the cheapest, by the
    median over its seeds of the rollout metric's wall time (a field: ``hnn.evaluation.ROLLOUT_SOLVER``; a learned map:
    its own steps); ``tied``: the others whose seeds' range of seconds overlaps its own, which the seeds
    cannot separate from it on cost. None where none was timed."""
    timed = {key: sorted(s for m in per_seed.values() if (s := (m.get("rollout") or {}).get("seconds")) is not None)
             for key, per_seed in cells.items()}
    timed = {key: seconds for key, seconds in timed.items() if seconds}
    if not timed:
        return None
    median = {key: statistics.median(seconds) for key, seconds in timed.items()}
    pick = min(timed, key=lambda key: (median[key], key[1], key[2]))
    low, high = timed[pick][0], timed[pick][-1]
    several = len(timed[pick]) > 1
    return {"kind": pick[0], "width": pick[1], "fraction": pick[2], "rollout_seconds": median[pick],
            "seconds_range": [low, high], "n_seeds": len(timed[pick]),
            "energy": spread[pick][0][0] if spread[pick][0] else None,
            "rollout": spread[pick][1][0] if spread[pick][1] else None,
            "tied": ([f"{k[0]}, width {k[1]}, {k[2]:g} of the data" for k in sorted(timed, key=median.get)
                      if k != pick and len(timed[k]) > 1 and timed[k][0] <= high] if several else None)}


def inseparable(per_kind: dict) -> dict:
    """``{"energy" | "rollout": {"best": kind, "tied": [kinds]}}`` of one scene's kinds at the default
    cell (``{kind: {seed: measured}}``): the best kind on the seeds' mean and the kinds whose seeds'
    range overlaps the best's, which the seeds cannot separate from it. Empty where the best has one seed."""
    out = {}
    for at, name in ((0, "energy"), (1, "rollout")):
        spread = {kind: s for kind, per_seed in per_kind.items()
                  if (s := scene_common.seed_spread([_key_metric(m)[at] for m in per_seed.values()])) is not None}
        if not spread:
            continue
        best = min(spread, key=lambda k: spread[k][0])
        if len(per_kind[best]) < 2:
            continue
        out[name] = {"best": best, "tied": [k for k in sorted(spread, key=lambda k: spread[k][0])
                                            if k != best and len(per_kind[k]) > 1
                                            and scene_common.seeds_overlap(spread[k], spread[best])]}
    return out


def run(args, argv: list[str], out: Path, studied: list[str], cuts: list[str]) -> tuple[dict, dict]:
    """The whole study of the scenes ``studied`` as ``args`` (the command's flags) ask: train, measure,
    pick the cards; ``(results, {run key: run folder or failure})``. ``argv`` is recorded as the
    command (folders as ``DIR``), ``cuts`` as what ``--quick`` cut."""
    steps = QUICK_STEPS if args.quick else None
    seeds = list(range(args.seeds))
    grid_seeds = list(range(args.grid_seeds or args.seeds))
    start = time.perf_counter()
    results = {"meta": {**provenance(), "command": "python analysis/scene_study.py " + " ".join(
        "DIR" if Path(a).is_absolute() else a for a in argv), "quick": args.quick, "quick_cuts": cuts, "seeds": seeds,
        "grid_seeds": grid_seeds, "jobs": args.jobs, "backend": args.backend,
        "starts": (scene_common.QUICK if args.quick else scene_common.FULL)["starts"],
        "horizon": (scene_common.QUICK if args.quick else scene_common.FULL)["horizon"]},
        "scenes": {}, "seconds": {}}

    # 1. train: every scene's kinds at the default cell (all seeds), the grid (its seeds), the D-HNN split
    rows = plan_rows(studied, args.quick)
    default_rows = [r for r in rows if r["cell"] == DEFAULT_CELL]
    grid_rows = [r for r in rows if r["cell"] != DEFAULT_CELL]
    dhnn_rows = [_row("real", DEFAULT_CELL, args.quick, DHNN_FIELDS, name="real-dhnn")] if "real" in studied else []
    tic = time.perf_counter()
    # the fits' rungs beside the kinds (scene_rungs): every fit at the default cell, the sampled layer's on the grid
    rungs, grid_rungs = rungs_of(args.quick)
    speed_kinds = QUICK_SPEED_KINDS if args.quick else None
    speed = speed_scenes(studied) if args.quick else None

    def measuring(models: int) -> list[plan.Stage]:
        # the models the training will leave, as if every run trains (the plan's units)
        will = {f"{row['row']}/{rung}/seed{seed}": out for batch_rows, batch_seeds, batch_rungs in
                ((default_rows, seeds, rungs), (grid_rows, grid_seeds, grid_rungs))
                for row in batch_rows for rung in batch_rungs for seed in batch_seeds}
        units = measure_units(studied, will, seeds, grid_rows, grid_seeds, speed_kinds, speed)
        return [data_stage(studied, args.quick), measure_stage(units, models, args.quick, len(dhnn_rows) and
                                                                 len(DHNN_MODELS))]
    runs, trained = train([(default_rows, seeds, steps, rungs), (grid_rows, grid_seeds, steps, grid_rungs),
                           # the D-HNN protocol's own 5000 steps (DHNN_FIELDS), or a quick run's
                           (dhnn_rows, [0], steps, DHNN_MODELS)], out, args, then=measuring,
                          share=QUICK_SHARES["train"] if args.quick else None)
    # the training's wall time, its datasets built and its configs timed included; "sweep" the runs' alone
    results["seconds"]["training"] = time.perf_counter() - tic
    results["seconds"]["sweep"] = trained["training"]

    # 2. measure, one thread per process (scene_measure): the rollouts here are batches of 4-15
    # states, which a second thread does not speed up; --jobs processes share the units
    tic = time.perf_counter()
    units = measure_units(studied, runs, seeds, grid_rows, grid_seeds, speed_kinds, speed)
    rollout_calls = scene_measure.QUICK_ROLLOUT_CALLS if args.quick else None
    results["meta"]["rollout_seconds"] = scene_measure.QUICK_ROLLOUT_SECONDS if args.quick else None
    results["meta"]["rollout_calls"] = rollout_calls
    measured, states, results["seconds"]["units"] = scene_measure.run(
        units, args.quick, args.jobs if args.backend == "local" else 1, rollout_calls)
    cells_by_scene = {}
    for task in studied:
        entry = {"divergence": (states.get(task) or {}).get("divergence"), "kinds": {}, "grid": {}, "grid_seeds": {},
                 "speed": {}}
        cells = {}
        for kind in task_rungs(task):
            result = measured.get(("kind", task, kind))
            if result is None:
                continue
            per_seed = result["per_seed"]
            entry["kinds"][kind] = {"per_seed": per_seed, **_across(per_seed)}
            cells[(kind, *DEFAULT_CELL)] = per_seed
            if "speed" in result:
                entry["speed"][kind] = result["speed"]
        entry["inseparable"] = inseparable({kind: cells[(kind, *DEFAULT_CELL)] for kind in entry["kinds"]})
        for kind in task_rungs(task):
            grid = {}
            for key, m in measured.get(("cells", task, kind), {}).items():
                cell, seed = key.rsplit("/seed", 1)
                grid.setdefault(cell, {})[int(seed)] = m
            for cell, per_seed in grid.items():
                # the grid tables show the first seed's numbers; the card reads every seed's
                entry["grid"][cell] = per_seed[min(per_seed)]
                if len(per_seed) > 1:
                    entry["grid_seeds"][cell] = _across(per_seed)
                width, fraction = cell.split("@")[1].split("x")
                cells[(kind, int(width), float(fraction))] = per_seed
        cells_by_scene[task] = cells
        results["scenes"][task] = entry
    if dhnn_rows:
        results["dhnn"] = _dhnn(runs, dhnn_rows[0])
    results["seconds"]["measure"] = time.perf_counter() - tic

    # 3. the cards; more seeds at a chosen grid cell the grid trained at fewer than the study's seeds
    tic = time.perf_counter()
    for task, cells in cells_by_scene.items():
        card = scene_card(cells)
        results["scenes"][task]["card"] = card
        if card and (card["width"], card["fraction"]) != DEFAULT_CELL and len(seeds) > card["n_seeds"]:
            row = _row(task, (card["width"], card["fraction"]), args.quick)
            more, _ = train([([row], seeds, steps, (card["kind"],))], out, args)
            runs.update(more)
            keys = {s: f"{row['row']}/{card['kind']}/seed{s}" for s in seeds}
            found = {s: (card["kind"], more[k]) for s, k in keys.items() if isinstance(more.get(k), Path)}
            scene = Scene(task, args.quick, states.get(task))
            with torch_threads(1):      # as the units' measurements (run_unit); the caller's count after
                card["seeds"] = _across(scene_measure.measure_models(scene, found))
        elif card and card["n_seeds"] > 1:
            card["seeds"] = _across(cells[(card["kind"], card["width"], card["fraction"])])
    results["seconds"]["cards"] = time.perf_counter() - tic
    results["seconds"]["total"] = time.perf_counter() - start

    return results, runs


def data_stage(studied, quick: bool) -> plan.Stage:
    """The plan's own cost: each scene's dataset built once (by the plan's first look at its runs; the runs and the
    truths read it from the run folder), at its declared ``TaskSpec.data_cost`` on the reference box."""
    return plan.Stage("build", len(studied), "datasets" if len(studied) != 1 else "dataset",
                      plan.reference_data_seconds(studied), "each scene's declared build on the reference box",
                      QUICK_SHARES["data"] if quick else None)


def measure_stage(units: dict, models: int, quick: bool, dhnn_models: int = 0) -> plan.Stage:
    """The plan's measuring stage of ``units`` and the D-HNN protocol's ``dhnn_models``: a quick study's from its
    declared costs (``scene_measure.quick_estimate``; a D-HNN model a model's), with its share and what it takes
    at most (every rollout stopped at its budget); a full study's timed as it runs."""
    what = "models (losses, energy MSE, rollout error; each kind's speed at equal accuracy)"
    if not quick:
        return plan.Stage("measure", models, what)
    estimate, most = scene_measure.quick_estimate(units)
    dhnn = dhnn_models * scene_measure.MODEL_SECONDS
    return plan.Stage("measure", models, what, estimate + dhnn,
                      f"each model's {scene_measure.MODEL_SECONDS:g} s, each speed study's "
                      f"{scene_measure.QUICK_SPEED_SECONDS:g} s, each scene's truth {scene_measure.TRUTH_SECONDS:g} s, "
                      f"a fit's training cost its recorded solve; at most {most + dhnn:.0f} s, every rollout "
                      f"stopped at {scene_measure.QUICK_ROLLOUT_CALLS} field calls", share=QUICK_SHARES["measure"])


def reference_plan(studied=None) -> list[plan.Stage]:
    """A quick study's plan on the reference box (``plan.reference_seconds``: declared costs, no data built):
    the plan's own timing of its configs (``plan.reference_timing``), its training (every fit at its
    ``QUICK_FIT_ROWS``), its datasets (``data_stage``) and its measuring (``measure_stage``); ``studied`` default:
    the quick study's own scenes (``quick_scenes``)."""
    studied = studied or quick_scenes(scene_common.scenes())  # the paper's page
    rows = [{k: v for k, v in row.items() if k != "fit_rows"} for row in plan_rows(studied, True)]
    default_rows = [r for r in rows if r["cell"] == DEFAULT_CELL]
    grid_rows = [r for r in rows if r["cell"] != DEFAULT_CELL]
    dhnn_rows = [_row("real", DEFAULT_CELL, True, DHNN_FIELDS, name="real-dhnn")] if "real" in studied else []
    rungs, grid_rungs = rungs_of(True)

    def fits_states(task, rung):
        return rung in task_rungs(task)
    jobs = []
    for batch, models in ((default_rows, rungs), (grid_rows, grid_rungs), (dhnn_rows, DHNN_MODELS)):
        jobs += [job for job in study.plan(batch, [0], Path("runs"), QUICK_STEPS, models)
                 if job.config.model in models and fits_states(job.task, job.config.model)]
        jobs += scene_rungs.jobs(batch, [0], Path("runs"), models, fits_states)
    jobs = [dataclasses.replace(job, expected_seconds=plan.reference_seconds(job, QUICK_FIT_ROWS)) for job in jobs]
    will = {job.key: Path("runs") for job in jobs}
    units = measure_units(studied, will, [0], grid_rows, [0], QUICK_SPEED_KINDS, speed_scenes(studied))
    return [plan.reference_timing(jobs), plan.training(jobs, 1, QUICK_SHARES["train"],
                                                       "each run's declared cost on the reference box"),
            data_stage(studied, True), measure_stage(units, len(jobs), True, len(dhnn_rows) and len(DHNN_MODELS))]


def measure_units(scenes, runs: dict, seeds: list[int], grid_rows: list[dict], grid_seeds: list[int],
                  speed_kinds=None, speed_scenes=None) -> dict:
    """``{key: scene_measure unit}``: per scene, each kind at the default cell (its seeds, and the
    speed study of the first seed where the scene has a truth to roll out, for the ``speed_kinds``
    and the ``speed_scenes`` only when given), then each kind's grid at ``grid_seeds`` (cells keyed
    ``kind@WxF/seedS``)."""
    units = {}
    for task in scenes:
        for kind in task_rungs(task):
            per_seed = {seed: str(run) for seed in seeds
                        if isinstance(run := runs.get(f"{task}@{DEFAULT_CELL[0]}x{DEFAULT_CELL[1]:g}/{kind}/seed{seed}"),
                                      Path)}
            if per_seed:
                # a fit's rung rolls out as its kind does: the speed study measures the kinds trained by Adam;
                # a learned map has one step, its data's: no ladder of integrators to time
                speed = (seeds[0] if seeds[0] in per_seed and "dts" in scene_settings(task)
                         and (speed_kinds is None or kind in speed_kinds) and "+" not in kind
                         and (speed_scenes is None or task in speed_scenes)
                         and not hnn.MODEL_KINDS[kind].steps else None)
                units[("kind", task, kind)] = ("kind", task, kind, per_seed, speed)
    for task in scenes:
        for kind in task_rungs(task):
            cells = {}
            for row in (r for r in grid_rows if r["task"] == task):
                for seed in grid_seeds:
                    run = runs.get(f"{row['row']}/{kind}/seed{seed}")
                    if isinstance(run, Path):
                        cells[f"{kind}@{row['cell'][0]}x{row['cell'][1]:g}/seed{seed}"] = (kind, str(run))
            if cells:
                units[("cells", task, kind)] = ("cells", task, cells)
    return units


def _across(per_seed: dict) -> dict:
    """Mean ± standard error across seeds of the main numbers of one kind, and the median of their
    training seconds (``scene_measure.median_cost_seconds``)."""
    out = {}
    for key in ("test_loss", "energy_mse_paper", "energy_mse_corrected"):
        values = [m[key][0] for m in per_seed.values() if m.get(key)]
        if values:
            out[key + "_seeds"] = list(hnn.metrics.mean_and_se(values))
    for key in ("error", "valid_time"):
        values = [m["rollout"][key] for m in per_seed.values() if m.get("rollout", {}).get(key) is not None]
        if values:
            out[key + "_seeds"] = list(hnn.metrics.mean_and_se(values))
    if (seconds := scene_measure.median_cost_seconds(per_seed)) is not None:
        out["train_seconds_median"] = seconds
    return out


def _dhnn(runs: dict, row: dict) -> dict:
    """The D-HNN protocol's numbers of our models trained on their split (seed 0)."""
    models, dataset = {}, None
    for kind in DHNN_MODELS:
        run = runs.get(f"{row['row']}/{kind}/seed0")
        if isinstance(run, Path):
            models[kind], saved, metrics = hnn.load_run(run)
            dataset = dataset or hnn.tasks.run_dataset("real", saved)
    if not models:
        return {}
    return {"ours": sm.dhnn_protocol(hnn.load_task("real"), models, dataset), "paper": sm.DHNN_PAPER,
            "config": DHNN_FIELDS}
