"""Scoring a saved run as the tables and cards do, and drawing it (``analysis/score.py`` is its command).

    scored = scoring.score_run(folder)          # {"test_loss", "energy_mse_<protocol>", "rollout", ...}
    print(scoring.describe(scored))
    scoring.plot_run(scored, out)               # the run's figures

Torch-free until a run is scored: ``run_folders`` and ``task_of`` read the input before anything heavy loads.
"""
from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import hnn


# ----------------------------------------------------------------------------------------------
# which runs, of which task (torch-free: the input is checked before anything heavy loads)


def run_folders(path: Path) -> list[Path]:
    """The saved runs at ``path``: the folder itself when it is one, else every run folder under it."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist; give a run folder (it holds args.json and model.tar) or a "
                                "folder of them (e.g. results-quick/runs)")
    if (path / "args.json").is_file():
        return [path]
    found = sorted({p.parent for p in path.rglob("args.json") if (p.parent / "model.tar").is_file()})
    if not found:
        raise FileNotFoundError(f"{path} holds no saved run (no folder with args.json and model.tar under it); train "
                                "one with an experiment-<task>/train.py or analysis/reproduce.py --quick")
    return found


def _task_fields(task: str) -> set[str]:
    """The keys a run of ``task`` records: its config's fields and the facts its task declares
    (``model_facts``: the chain's ``constraints``, the bodies of an N-body task)."""
    config = hnn.tasks.task_config(task)
    return {f.name for f in dataclasses.fields(config)} | set(config.model_facts())


def task_of(args: dict) -> str:
    """The task a saved run's ``args`` (args.json) belong to: among the tasks whose config has every field
    they hold, the one its ``name`` starts with (``spring``, ``spring-w16-f0.25``, ``3body-clean``), else the
    only one; a ValueError where that leaves none or several."""
    recorded = set(args) - {"threads", "kind", "dataset_cache_key", "unit_scales", "loss_weights", "dt"}
    tasks = [task for task in hnn.tasks.task_names() if recorded <= _task_fields(task)]
    named = [task for task in tasks if str(args.get("name", "")).split("-")[0] == task]
    if len(named) == 1 or len(tasks) == 1:
        return (named or tasks)[0]
    raise ValueError(f"cannot tell the task of the run named {args.get('name')!r} (its settings fit "
                     f"{', '.join(tasks) or 'no task here'}); pass --task")


# ----------------------------------------------------------------------------------------------
# the numbers


_SCENES: dict = {}      # this process's scene truths, one per task


def _scene(task: str):
    from hnn_analysis.scenes.scene_common import Scene
    if task not in _SCENES:
        _SCENES[task] = Scene(task, quick=False)
    return _SCENES[task]


def score_run(directory, task: str | None = None, horizon: float | None = None, energy: str | None = None) -> dict:
    """The numbers of one saved run: ``{"run", "task", "kind", "test_loss", "energy_mse_<protocol>": [mse, se],
    "rollout": {"error", "valid_time", ...}, "divergence"}`` for a task's run (as the scene study measures it:
    ``Scene.measure``), or the measured card's row (``"prediction_error"``, ``"valid_time"``, ``"naive"``, ...)
    for a run of ``experiment-measured``. ``horizon``, ``energy``: the measured study's ``--horizon`` and
    ``--energy``."""
    directory = Path(directory)
    args = json.loads((directory / "args.json").read_text())
    task = task or task_of(args)
    if task == "measured":
        return _score_measured(directory, args, horizon, energy)
    scene = _scene(task)
    tic = time.perf_counter()
    out = scene.measure(args["model"], directory)
    out.update(run=str(directory), task=task, kind=args["model"], seconds=time.perf_counter() - tic,
               divergence=(getattr(scene, "divergence", None) or {}).get("divergence_time"),
               protocols={name: p.describe() for name, p in hnn.task_spec(task).protocols.items()
                          if hasattr(p, "describe")})
    return out


def _measured(args: dict, horizon: float | None):
    """``(data module, recording, held-out tails)`` of a measured run's file, as the study reads it."""
    from hnn_analysis.scenes import measured_metrics as mm
    data = hnn.load_task("measured")
    rec = data.load(*(args.get(key) for key in ("data", "time", "q", "v", "p", "trial", "periodic", "dxdt")))
    return data, rec, mm.Heldout(data, rec, args["test_fraction"], horizon, args["max_gap"])


def _score_measured(directory: Path, args: dict, horizon: float | None, energy: str | None) -> dict:
    from hnn_analysis.scenes import measured_metrics as mm
    data, rec, held = _measured(args, horizon)
    model = mm.Model(data, directory, json.loads((directory / "scale.json").read_text()), rec.state)
    tic = time.perf_counter()
    out = {"run": str(directory), "task": "measured", "kind": args["model"], "data": args["data"],
           "hidden_dim": args["hidden_dim"], "train_fraction": args["train_fraction"], "seed": args["seed"],
           "params": model.params, "test_loss": model.metrics["test_loss"], "horizon": held.horizon,
           "naive": held.naive, "spread": held.spread, **mm.measure(model, held, mm.energy_function(energy, rec))}
    out["seconds"] = time.perf_counter() - tic
    return out


def _g(value) -> str:
    return "n/a" if value is None else f"{value:.3g}"


def describe(score: dict) -> str:
    """One run's numbers in words, a line each."""
    head = f"{score['task']} {score['kind']}: {score['run']}"
    if score["task"] == "measured":
        pe, naive = score["prediction_error"], score["naive"]
        loss = ("next-state MSE" if score["kind"] in hnn.MODEL_KINDS and hnn.MODEL_KINDS[score["kind"]].steps
                else "derivative MSE")
        lines = [head, f"  test loss {_g(score['test_loss'])} ({loss} on the scaled states)",
                 f"  prediction error at {score['horizon']:.4g} s: median {_g(pe['median'])}, mean {_g(pe['mean'])} "
                 f"over {pe['starts']} starts (naive q + h v: {_g(naive['median'])}; the positions' spread "
                 f"{_g(score['spread'])})",
                 f"  valid time {_g(score['valid_time']['median'])} s (median over {score['valid_time']['starts']} starts)"]
        if "energy_drift" in score:
            lines.append(f"  energy drift {_g(score['energy_drift']['model'])} (measured {_g(score['energy_drift']['measured'])})")
        return "\n".join(lines)
    lines = [head, f"  test loss {_g(score['test_loss'][0])} ± {_g(score['test_loss'][1])}"]
    for key, value in score.items():
        if key.startswith("energy_mse_"):
            name = key[len("energy_mse_"):]
            how = score.get("protocols", {}).get(name, name)
            lines.append(f"  energy MSE, {name} protocol: {_g(value[0])} ± {_g(value[1])} ({how})")
    if "rollout" in score:
        r = score["rollout"]
        valid = (f"; valid time {_g(r['valid_time'])} of {_g(r['horizon'])}" if r.get("valid_time") is not None else "")
        chaos = "" if score.get("divergence") is None else (
            " (the truth itself, from starts 1e-4 apart, stays within 0.1 over the horizon)"
            if score["divergence"] >= r["horizon"] else
            f" (the truth itself diverges from starts 1e-4 apart after {_g(score['divergence'])}: no model can be valid longer)")
        lines.append(f"  rollout error {_g(r['error'])} (the scene cards' protocol){valid}{chaos}")
    return "\n".join(lines)


def table(scores: list[dict]) -> str:
    """Several runs' numbers as a markdown table, the energy protocols a column each."""
    protocols = list(dict.fromkeys(k for s in scores for k in s if k.startswith("energy_mse_")))
    rollouts, measured = any("rollout" in s for s in scores), any("prediction_error" in s for s in scores)
    head = ["run", "task", "kind", "test loss", *(f"energy MSE, {p[len('energy_mse_'):]}" for p in protocols),
            *(["rollout error"] if rollouts else []), *(["valid time"] if rollouts or measured else []),
            *(["prediction error (naive)"] if measured else [])]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for s in scores:
        loss = s["test_loss"][0] if isinstance(s["test_loss"], list) else s["test_loss"]
        rollout = s.get("rollout") or {}
        valid = s["valid_time"]["median"] if isinstance(s.get("valid_time"), dict) else rollout.get("valid_time")
        cells = [Path(s["run"]).name, s["task"], s["kind"], _g(loss), *(_g(s[p][0]) if p in s else "" for p in protocols)]
        cells += [_g(rollout.get("error")) if rollout else ""] if rollouts else []
        cells += [_g(valid)] if rollouts or measured else []
        cells += [f"{_g(s['prediction_error']['median'])} ({_g(s['naive']['median'])})" if "prediction_error" in s
                  else ""] if measured else []
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# the figures


def plot_run(score: dict, out: Path, horizon: float | None = None) -> list[Path]:
    """The figures of one scored run into ``out``: the task's figures that draw any one model
    (``registry.RUN_FIGURES``), or a measured run's tails; returns the files written."""
    directory, out = Path(score["run"]), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    before = set(out.iterdir())
    if score["task"] == "measured":
        from hnn_analysis.scenes import measured_figure, measured_metrics as mm
        data, rec, held = _measured(json.loads((directory / "args.json").read_text()), horizon)
        model = mm.Model(data, directory, json.loads((directory / "scale.json").read_text()), rec.state)
        measured_figure.tails_figure({score["kind"]: model}, held, out / f"{directory.name}-tails.png",
                                     Path(score["data"]).name)
    else:
        from hnn_analysis.paper import registry, study
        trained, _ = study.load_runs(score["task"], {score["kind"]: directory})
        registry.draw_figures(trained, registry.evaluate(trained), out, only=registry.RUN_FIGURES)
    return sorted(set(out.iterdir()) - before) or sorted(out.iterdir())


def plot_kinds(scores: list[dict], out: Path, horizon: float | None = None) -> list[Path]:
    """Per data file of the measured runs among ``scores``, one tails figure with each kind's best run
    (lowest median prediction error)."""
    from hnn_analysis.scenes import measured_figure, measured_metrics as mm
    written = []
    by_file: dict = {}
    for s in (s for s in scores if s["task"] == "measured"):
        best = by_file.setdefault(s["data"], {})
        if s["kind"] not in best or s["prediction_error"]["median"] < best[s["kind"]]["prediction_error"]["median"]:
            best[s["kind"]] = s
    for data_file, best in by_file.items():
        first = Path(next(iter(best.values()))["run"])
        data, rec, held = _measured(json.loads((first / "args.json").read_text()), horizon)
        models = {kind: mm.Model(data, Path(s["run"]), json.loads((Path(s["run"]) / "scale.json").read_text()),
                                 rec.state) for kind, s in best.items()}
        written.append(measured_figure.tails_figure(models, held, Path(out) / f"{Path(data_file).stem}-kinds.png",
                                                    Path(data_file).name))
    return written


def plot_score(score: dict, out: Path, horizon: float | None = None) -> list[Path]:
    """The figures of one scored run into ``out`` (``plot_run``'s for a measured run): the task's figures that
    draw one model (``registry.RUN_FIGURES``), titled by what the run is ("Hamiltonian NN (library fit)" where a
    least-squares fit found its weights); a learned map, which has no field to draw, its energy over its own
    steps. Returns the files written."""
    if score["task"] == "measured":
        return plot_run(score, out, horizon)
    from hnn_analysis.paper import figures, registry, study
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    before = set(out.iterdir())
    kind, fit = score["kind"], score.get("fit", "adam")
    label = kind if fit == "adam" else f"{figures.NAMES.get(kind, kind)} ({fit} fit)"
    trained, _ = study.load_runs(score["task"], {label: Path(score["run"])})
    steps = any(hnn.interface.declared(model).steps for model in trained.models.values())
    only = [name for name in registry.RUN_FIGURES if name == "energy" or not steps]
    registry.draw_figures(trained, registry.evaluate(trained), out, only=only)
    return sorted(set(out.iterdir()) - before) or sorted(out.iterdir())
