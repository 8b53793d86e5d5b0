"""The scene study's measuring, as units of work that run here or in ``--jobs`` worker processes.

    measured, states, seconds = scene_measure.run(units, jobs=2)      # {unit key: result}, as the units finish

A unit is plain data (it crosses process boundaries): ``("kind", task, kind, {seed: run folder},
seed of the speed study or None)`` or ``("cells", task, {cell key: (kind, run folder)})``.
Each scene's truth (``scene_common.Scene``) is built once, by the first unit of that scene, and
handed to the others as arrays, so a second worker does not integrate it again.

Within a unit the models of one scene share their energy protocols' truth: ``measure_models``
evaluates them in one ``hnn.evaluate_energy`` call per protocol (the truth is integrated once, each
model rolled out as alone, so the numbers equal one model's call). The rollout error stays one
rollout per model, because its wall time is the model's rollout cost in the Pareto plot.

A model's training seconds are its ``hnn_analysis.training_cost`` (measured in the study's own process,
beside at most its other worker); the recorded wall time of a run says more about what else the
machine did while it trained.

A quick study gives each model's rollout its share of the measuring's seconds in field calls at the reference
box's rate (``QUICK_ROLLOUT_CALLS``, ``hnn.evaluation.rollout_budget``): a rollout stiff along its path stops there,
the same on every box, and the model's entry says so (``energy_stopped``, the rollout's ``stopped`` paths) where a
full study would wait for it. A quick study's fit is priced by the seconds its run recorded (its solve), not
solved again.
"""
from __future__ import annotations

import concurrent.futures
import multiprocessing
import statistics
import time
from pathlib import Path

import contextlib


import hnn
from hnn.sweeps import sweep
from hnn.threads import torch_threads
from hnn_analysis import plan
from hnn_analysis.paper import registry, study
from hnn_analysis.scenes import scene_common
from hnn_analysis.training_cost import training_cost

def cost_seconds(measured: dict) -> float | None:
    """A measured model's training seconds: its ``training_cost`` where the study measured one,
    else the run's recorded wall time."""
    cost = measured.get("train_cost")
    return cost["seconds"] if cost else measured.get("train_seconds")


def median_cost_seconds(per_seed: dict) -> float | None:
    """The median of ``cost_seconds`` over a model's seeds (``{seed: measured}``), None where none has
    one: one timing moves between sittings by more than two models of equal size differ."""
    values = sorted(c for m in per_seed.values() if (c := cost_seconds(m)) is not None)
    return statistics.median(values) if values else None


def measure_models(scene, runs: dict, protocols: bool = True) -> dict:
    """``{key: measured}`` of ``runs`` (``{key: (kind, run folder)}``, models of ``scene``): each as
    ``Scene.measure`` gives it, plus ``train_cost`` (``training_cost``). The energy protocols run
    once for all of them (one truth); a task with its own ``evaluate`` (pixels) goes model by model."""
    if not runs:
        return {}
    if hnn.task_spec(scene.task).evaluate is not None:
        return {key: scene.measure(kind, directory, protocols) | {"train_cost": _cost(scene.task, directory,
                                                                                        scene.quick)}
                for key, (kind, directory) in runs.items()}
    tic = time.perf_counter()
    trained, rows = study.load_runs(scene.task, {key: directory for key, (_, directory) in runs.items()})
    energy = registry.evaluate(trained, scene.trials) if protocols else {}
    shared = (time.perf_counter() - tic) / len(runs)
    out = {}
    for key, (_, directory) in runs.items():
        model = trained.models[key]
        m = scene_common.saved_numbers(rows[key], model, directory)
        for name, result in energy.items():
            if result[key].get("stopped"):      # its rollout stopped at its budget (a quick study's): said, no number
                m.setdefault("energy_stopped", {})[name] = result[key]["stopped"]
                continue
            if result[key]["mse"] is None:      # a protocol that does not apply to a learned map: why, not a number
                m.setdefault("energy_not_applicable", {})[name] = result[key]["why"]
                continue
            m[f"energy_mse_{name}"] = [result[key]["mse"], result[key]["mse_se"]]
        tic = time.perf_counter()
        if scene.truth is not None:
            m["rollout"] = scene.rollout(model)
        m["evaluate_seconds"] = shared + time.perf_counter() - tic
        m["train_cost"] = _cost(scene.task, directory, scene.quick)
        out[key] = m
    return out


def _cost(task: str, directory, quick: bool = False) -> dict | None:
    """A model's ``training_cost``; None for a quick study's fit, whose cost is the solve its run recorded
    (``cost_seconds`` reads it): measured again, it is solved again (the plan's "fits solved again")."""
    args = hnn.load_run(directory)[1]
    if quick and args.get("fit", "adam") != "adam":
        return None
    return training_cost(task, args, *(QUICK_BURSTS if quick else ()))


# ----------------------------------------------------------------------------------------------
# units, here or in worker processes


def _scene(task: str, quick: bool, state: dict | None, cache: dict):
    if task not in cache:
        cache[task] = scene_common.Scene(task, quick, state)
    return cache[task]


_SCENES: dict = {}      # this process's scenes, by task (a worker keeps them between its units)


def rollouts(unit: tuple) -> int:
    """The models' rollouts of a unit that a ``rollout_budget`` bounds: each model's under every energy protocol
    of its task and its rollout error (a task with its own evaluation: the rollout error alone)."""
    spec = hnn.task_spec(unit[1])
    per_model = 1 + (len(spec.protocols) if spec.evaluate is None else 0)
    return per_model * (len(unit[3]) if unit[0] == "kind" else len(unit[2]))


def run_unit(unit: tuple, quick: bool, state: dict | None = None,
             rollout_calls: int | None = None) -> tuple[dict, dict | None, float]:
    """``(result, the scene's state, seconds)`` of one unit (see the module's docstring), on one thread; each
    model's rollouts within ``rollout_calls`` field calls each where given (``hnn.evaluation.rollout_budget``);
    ``seconds``: its wall time in the process that measured it (what a plan's declared costs are set from)."""
    tic = time.perf_counter()
    # rollouts of 4-15 states: a second thread only adds contention; the caller's count back after
    with torch_threads(1), (contextlib.nullcontext() if rollout_calls is None else hnn.evaluation.rollout_budget(
            calls=rollout_calls, why=f"the quick study's {QUICK_ROLLOUT_SECONDS:g} s of a model's rollout at the "
                                     "reference box's rate")):
        result, state = _run_unit(unit, quick, state)
    return result, state, time.perf_counter() - tic


def _run_unit(unit: tuple, quick: bool, state: dict | None) -> tuple[dict, dict | None]:
    unit_type, task = unit[0], unit[1]
    scene = _scene(task, quick, state, _SCENES)
    if unit_type == "kind":
        _, _, kind, per_seed, speed_seed = unit
        measured = measure_models(scene, {seed: (kind, Path(d)) for seed, d in per_seed.items()})
        result = {"per_seed": measured}
        if speed_seed is not None:
            result["speed"] = scene_common.speed_study(scene, kind, hnn.load_run(Path(per_seed[speed_seed]))[0], quick)
    elif unit_type == "cells":
        _, _, runs = unit
        result = measure_models(scene, {k: (kind, Path(d)) for k, (kind, d) in runs.items()})
    else:
        raise ValueError(f"unknown unit type {unit_type!r}")
    return result, scene.state()


# a kind's speed study (its ladder and three drift runs of up to DRIFT_BUDGET s) against one model's measuring
# (spring, measured: about 30 s against about 1.5 s)
SPEED_WEIGHT = 20
# a quick study's measuring, on a quiet 2-core box, for its plan: a model's seconds (its run loaded, its losses,
# its training cost's one short burst, its rollouts when healthy), a quick speed study's (its ladder timed once,
# three drift runs of scene_common.QUICK's drift_budget) and a scene's truth (built by its first unit). Measured
# (``scene_study.json``'s units, the quick study at 1.2 load on the 2-core box, 2026-12-06): a unit of one model
# 0.06-1.2 s, median 0.4 (the 3-body library's 7.5 s, its rollouts stopped at their budget); the spring's speed study
# about 0.7 s beside its model's; a scene's first unit 0-1.7 s over a model's (the 3-body's the dearest). A fit's
# training cost is the solve its run recorded (nothing solved again)
MODEL_SECONDS = 0.5
QUICK_SPEED_SECONDS = 2.0
TRUTH_SECONDS = 1.0
# a quick study's budget of each model rollout (under each energy protocol, and for its rollout error), in seconds
# on the reference box and so in field calls (QUICK_ROLLOUT_CALLS, the same on every box): the 3-body library's,
# stiff off the orbits, passed 20000 calls on one trial of 15 and ran 350 s; of the healthy models of a quick study
# the hungriest rollout made 4412 calls (the spring's hnn+swim, its rollout error; every other under 4000), so 6000
# stop the library alone. A budget in wall seconds stopped two healthy mechanical models on a loaded box (their
# calls cost more there), which a budget in calls does not
QUICK_ROLLOUT_SECONDS = 3.0
QUICK_ROLLOUT_CALLS = round(QUICK_ROLLOUT_SECONDS / plan.REFERENCE_FIELD_CALL_SECONDS)
# a quick study's training cost of a model: one short burst, as a plan's (hnn_analysis.plan)
QUICK_BURSTS = (1, 0.05)


def quick_estimate(units: dict) -> tuple[float, float]:
    """``(estimate, at most)`` of a quick study's measuring of ``units`` on the reference box: each model's
    ``MODEL_SECONDS``, each speed study's ``QUICK_SPEED_SECONDS`` and each scene's ``TRUTH_SECONDS``; at most,
    every rollout stopped at its ``QUICK_ROLLOUT_CALLS`` (``QUICK_ROLLOUT_SECONDS`` there) besides."""
    models = sum(len(unit[3]) if unit[0] == "kind" else len(unit[2]) for unit in units.values())
    speeds = sum(unit[0] == "kind" and unit[4] is not None for unit in units.values())
    scenes = len({unit[1] for unit in units.values()})
    estimate = models * MODEL_SECONDS + speeds * QUICK_SPEED_SECONDS + scenes * TRUTH_SECONDS
    return estimate, estimate + sum(rollouts(unit) for unit in units.values()) * QUICK_ROLLOUT_SECONDS


def _weight(unit: tuple) -> float:
    """A unit's share of the measuring: its models, and ``SPEED_WEIGHT`` for a speed study."""
    if unit[0] == "kind":
        return len(unit[3]) + (SPEED_WEIGHT if unit[4] is not None else 0)
    return len(unit[2])


def _describe(unit: tuple) -> str:
    """A unit in a progress line: ``'spring  hnn'`` or ``'spring  hnn at 3 grid runs (cells x seeds)'``."""
    if unit[0] == "kind":
        return f"{unit[1]:7s} {unit[2]}" + (f" ({len(unit[3])} seeds)" if len(unit[3]) > 1 else "")
    kind = next(iter(unit[2].values()))[0] if unit[2] else ""
    return f"{unit[1]:7s} {kind} at {len(unit[2])} grid run{'s' if len(unit[2]) != 1 else ''} (cells x seeds)"


def run(units: dict, quick: bool, jobs: int = 1, rollout_calls: int | None = None) -> tuple[dict, dict, dict]:
    """``({key: result}, {task: the scene's state}, {"kind spring hnn": its seconds})`` of ``units`` (``{key: unit}``,
    keys ``(unit type, task, kind)``):
    here (``jobs`` 1) or in ``jobs`` worker processes, each scene's first unit first (it builds the scene's truth,
    which the others reuse); each model's rollouts within ``rollout_calls`` where given (``run_unit``)."""
    results, states, seconds, progress = {}, {}, {}, sweep.Progress(len(units))
    # the time left by the units' weights: a model a model, a kind's speed study SPEED_WEIGHT models; with a
    # budget, each unit's seconds at most (quick_estimate), so that no unit's stop can swell the time left
    weights = {key: _weight(unit) if rollout_calls is None else quick_estimate({key: unit})[1]
               for key, unit in units.items()}
    ahead, measured = plan.Ahead(sum(weights.values())), [0.0]

    def said(key) -> str:
        measured[0] += weights[key]
        return f"  {progress.advance()} {_describe(units[key])} measured" + ahead.tag(measured[0])
    print(f"  {progress.tag()} measuring {len(units)} unit{'s' if len(units) != 1 else ''} of models", flush=True)
    if jobs <= 1:
        for key, unit in units.items():
            results[key], states[unit[1]], seconds[" ".join(key)] = run_unit(unit, quick, None, rollout_calls)
            print(said(key), flush=True)
        return results, states, seconds
    by_task: dict[str, list] = {}
    for key, unit in units.items():
        by_task.setdefault(unit[1], []).append(key)
    context = multiprocessing.get_context("spawn")     # a fresh interpreter: no torch state copied by fork
    with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=context) as pool:
        # the first unit of every scene now; the rest of a scene once its truth is known
        running = {pool.submit(run_unit, units[keys[0]], quick, None, rollout_calls): keys[0]
                   for keys in by_task.values()}
        waiting = {task: keys[1:] for task, keys in by_task.items()}
        while running:
            finished, _ = concurrent.futures.wait(running, return_when=concurrent.futures.FIRST_COMPLETED)
            for future in finished:
                key = running.pop(future)
                try:
                    results[key], state, seconds[" ".join(key)] = future.result()
                except Exception as err:      # name the unit now, not after the other workers' units end
                    pool.shutdown(wait=False, cancel_futures=True)
                    raise RuntimeError(f"measuring {_describe(units[key])} failed: {type(err).__name__}: {err}") from err
                print(said(key), flush=True)
                task = units[key][1]
                if task not in states:
                    states[task] = state
                    for other in waiting.pop(task, []):
                        running[pool.submit(run_unit, units[other], quick, state, rollout_calls)] = other
    return results, states, seconds
