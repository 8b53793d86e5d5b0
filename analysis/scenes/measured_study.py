"""The scene study of your own measurements: which model kind does this file need?

    python analysis/scene_study.py --data osc.csv --time t --q x --v v --trial run --jobs 2 --out results/osc
    python analysis/scene_study.py --data osc.csv --q x --v v --quick        # a smoke run (budget 120 s)

Every model kind that fits the coordinates (``experiment-measured``: all of ``--model``'s kinds on [q, v];
on [q, p] all but second_order; with some positions periodic and others not, mechanical and
second_order are left out) trains over a small grid of widths and training fractions, in one
sweep (``scene_common.train``: reused runs, ``--jobs`` processes, grouped training). Each is then
measured on the held-out tail of every trial (``measured_metrics``): the prediction error at
``--horizon`` seconds beside the naive extrapolation's, the valid prediction time, the energy
drift with ``--energy``, the derivative loss (on the scaled states, so dimensionless) and the
training (``hnn_analysis.training_cost``, one thread) and rollout seconds. The card (``measured_card``: one
decision its sentences and ``chosen`` both read) picks the smallest model (parameters, then training rows,
then training seconds) enough: within ``CARD_FACTOR`` of the best median prediction error and under its
thresholds of the naive error and the positions' spread; where none is, it says so. Writes ``<out>/scene.json`` and ``<out>/scene.md``; ``--update-docs`` files the
card under the data file's name in docs/measured-scenes.json and rewrites the README's rows of
measured scenes from that file.
"""
from __future__ import annotations

import json
import shlex
import time
from pathlib import Path

import numpy as np

import hnn
from hnn.io import write_json
from hnn_analysis import commands, pages, plan
from hnn.sweeps import sweep
from hnn_analysis.paper import study
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import provenance
from hnn_analysis.scenes import measured_card, measured_metrics as mm, scene_common, scene_rungs, scene_tables
from hnn_analysis.scenes.measured_card import error_range, models
from hnn_analysis.scenes.measured_inputs import TASK, Inputs, check
from hnn_analysis.training_cost import training_cost

WIDTHS, FRACTIONS = (32, 200), (0.5, 1.0)
QUICK_WIDTHS, QUICK_FRACTIONS = (64,), (1.0,)
REGISTRY = "docs/measured-scenes.json"      # the cards --update-docs files, by data file name


def _kinds(columns: dict) -> list[str]:
    """The kinds that fit these coordinates (each built on the data and handed to its objective's checks), then
    the fits' rungs of them (``scene_rungs``) whose fit applies."""
    config = hnn.tasks.task_config(TASK, columns)
    dataset = config.dataset()
    kinds = []
    for kind in hnn.cli.model_choices(type(config)):
        if not hnn.MODEL_KINDS[kind].studied:
            continue
        if hnn.MODEL_KINDS[kind].steps:     # its rollouts here run at the file's own times, not a map's one step
            print(f"  {kind}: a learned map, left out (this study rolls out at your file's times; docs/maps.md)",
                  flush=True)
            continue
        try:
            # what its run would build (a small one): the model, its objective on these columns, the units
            hnn.prepare(hnn.tasks.task_config(TASK, {**columns, "model": kind, "hidden_dim": 4}), dataset)
        except (ValueError, KeyError) as err:      # refused by its checks, or it needs what the file lacks
            print(f"  {kind}: does not fit these coordinates ({err})", flush=True)
            continue
        kinds.append(kind)
    for rung in scene_rungs.fit_rungs(kinds):      # the fits' rungs of those kinds, where the fit applies too
        run = hnn.tasks.task_config(TASK, {**columns, "model": scene_rungs.kind_of(rung), "fit": scene_rungs.fit_of(rung)})
        try:
            hnn.fits.check_config(run, hnn.MODEL_KINDS[run.kind].coordinates)
        except ValueError as err:
            print(f"  {rung}: does not fit this data ({err})", flush=True)
            continue
        kinds.append(rung)
    return kinds


def quick_cuts(columns: dict, seeds: int = 1) -> list[str]:
    """What ``--quick`` cuts from the study of a file at ``seeds`` seeds, one phrase each, as ``run`` prints them."""
    steps = hnn.tasks.task_config(TASK, columns).total_steps
    return [f"{study.QUICK_STEPS} training steps a model of {steps}",
            f"grid: widths {', '.join(map(str, QUICK_WIDTHS))} x fractions {', '.join(map(str, QUICK_FRACTIONS))} "
            f"of {', '.join(map(str, WIDTHS))} x {', '.join(map(str, FRACTIONS))}",
            *([f"{seeds} seed{'s' if seeds > 1 else ''} a model of {scene_common.SEEDS}"]
              if seeds < scene_common.SEEDS else [])]


def _rows(columns: dict, quick: bool) -> list[dict]:
    widths, fractions = (QUICK_WIDTHS, QUICK_FRACTIONS) if quick else (WIDTHS, FRACTIONS)
    stem = Path(columns["data"]).stem
    return [{"row": f"{stem}@{w}x{f:g}", "task": TASK, "cell": (w, f),
             "fields": {**columns, "hidden_dim": w, "train_fraction": f, "name": f"{stem}-w{w}-f{f:g}"}}
            for w in widths for f in fractions]


def velocity_mismatch(columns: dict) -> list[float] | None:
    """Per position, RMS(dq/dt - v) / RMS(v) on the training rows (dq/dt by the task's finite differences):
    how far the velocity columns are from the derivatives of the positions (None on [q, p])."""
    d = hnn.tasks.task_config(TASK, columns).dataset()
    if d["state"] != "velocity":
        return None
    n = d["x"].shape[1] // 2
    gap = d["dxdt"][:, :n] - d["x"][:, n:]
    return [float(v) for v in np.sqrt((gap ** 2).mean(0)) / np.sqrt((d["x"][:, n:] ** 2).mean(0))]


def _card(rows: list[dict], naive: dict, spread: float) -> tuple[dict | None, list[str]]:
    """``(chosen, sentences)`` of the card, both from its one ``measured_card.Decision``: the smallest model
    enough (within ``CARD_FACTOR`` of the best mean median error, under ``BEATS_NAIVE`` of the naive one and
    ``VALID_FRACTION`` of the tails' RMS spread of positions ``spread``), else, where none is, the smallest within
    ``CARD_FACTOR``, called NOT enough (a chaotic scene's best model may be neither)."""
    decision = measured_card.decide(rows, naive, spread)
    if decision is None:
        return None, ["no model was measured"]
    return measured_card.chosen(decision), measured_card.sentences(decision)


def markdown(result: dict) -> str:
    meta, naive = result["meta"], result["naive"]
    lines = []
    if meta["quick"]:
        cut = meta.get("quick_cuts")
        lines += [f"**QUICK smoke run ({study.QUICK_STEPS} steps per model): not the study's settings.**"
                  + (f" Cut: {'; '.join(cut)}." if cut else ""), ""]
    lines += [f"# Scene card: {result['scene']}", "",
              generated_by(meta, f"torch {meta['torch']}, {meta['cores']} cores, --jobs {meta['jobs']}")
              + f". Wall time: training {result['seconds']['training']:.0f} s, "
              f"measuring {result['seconds']['measure']:.0f} s, total {result['seconds']['total']:.0f} s.", "",
              *result["card"], "",
              f"Prediction error: from each of {naive['starts']} held-out samples with a measured sample "
              f"{meta['horizon']:.4g} s later, the norm of the position error there ({meta['units']}; angles wrapped), "
              f"median / mean over starts; each model's row gives its seeds' mean of the median, their range, and their "
              f"mean of the mean. Naive: q(t) + h v(t): {naive['median']:.4g} / {naive['mean']:.4g}. Valid "
              f"time: median first time the error exceeds {mm.VALID_FRACTION:g} of the tail's RMS spread (s). Test "
              "loss: the derivative MSE on the scaled states (dimensionless). Valid time, test loss, energy drift, "
              "train s (one thread, controlled) and rollout s: means over the seeds.", ""]
    if meta.get("assumes"):
        lines += [f"Note: {meta['assumes']}.", ""]
    lines += [line for note in meta.get("notes") or [] for line in (f"Note: {note}.", "")]
    if meta.get("velocity_mismatch"):
        lines += ["Velocity columns against the finite-difference derivatives of the positions, RMS(dq/dt - v) / "
                  "RMS(v) on the training rows: " + ", ".join(f"{name} {m:.3g}" for name, m in zip(
                      columns_of(meta["columns"]["q"]), meta["velocity_mismatch"])) + " (kinds that take dq/dt = v "
                  "exactly, second_order and mechanical, and hnn reading v as p, inherit this gap; the baseline learns "
                  "dq/dt freely).", ""]
    table = models(result["rows"])
    energy = any(m["energy_drift"] for m in table.values())
    lines += ["| model | width | fraction | params | seeds | prediction error median: mean over seeds (range) / mean | "
              "valid time s | test loss | " + ("energy drift (measured) | " if energy else "") + "train s | rollout s |",
              "| --- | ---: | ---: | ---: | ---: | --- | ---: | --- | " + ("--- | " if energy else "") + "---: | ---: |"]
    for m in sorted(table.values(), key=lambda m: m["error"][0]):
        drift = m["energy_drift"]
        lines.append(f"| {m['kind']} | {m['hidden_dim']} | {m['train_fraction']:g} | {m['params']} | {len(m['seeds'])} | "
                     f"{error_range(m)} / {m['error_mean']:.4g} | {m['valid_time']:.3g} | {m['test_loss']:.3g} | "
                     + (f"{drift['model']:.3g} ({drift['measured']:.3g}) | " if drift else "| " if energy else "")
                     + f"{m['train_seconds']:.3g} | {m['rollout_seconds']:.3g} |")
    # the naive extrapolation as the table's last row: its error, and an empty cell for every other column
    lines.append(f"| naive q + h v | | | | | {naive['median']:.4g} / {naive['mean']:.4g} | | | "
                 + ("| " if energy else "") + "| |")
    return "\n".join(lines) + "\n"


def guide(registry: dict) -> str:
    """The README's rows of measured scenes, from the filed cards (each card's command is in
    docs/measured-scenes.json, and the shipped scenes' commands in docs/measured.md)."""
    lines = ["| measured scene | a model that is enough (its seeds' mean within 2x of the best) | median prediction "
             "error: seeds' mean (range); naive | seeds | seeds cannot separate | horizon | cheapest to train that is "
             "enough | made |",
             "| --- | --- | --- | ---: | --- | ---: | --- | --- |"]
    for name, entry in sorted(registry.items()):
        c = entry["chosen"]
        pe, n = c["prediction_error"], c.get("n_seeds", 1)
        spread = f" ({pe['min']:.3g}-{pe['max']:.3g})" if n > 1 else ""
        pick = scene_rungs.describe(c['kind'], c['hidden_dim'], c['train_fraction'])
        if c.get("enough") is False:         # a card filed before "enough" had its thresholds reads as it was filed
            pick = (f"none is enough (over {measured_card.BEATS_NAIVE:g} of the naive error or {mm.VALID_FRACTION:g} of "
                    f"the spread); smallest within {scene_common.CARD_FACTOR:g}x of the best: {pick}")
        lines.append(f"| {name} | {pick} | "
                     f"{pe['median']:.3g}{spread}; naive {entry['naive']['median']:.3g} ({entry['units']}) | {n} | "
                     f"{scene_tables.unsettled(c)} | "
                     f"{entry['horizon']:.3g} s | {scene_tables.cheapest_words(c)} | ({entry['date']}, commit "
                     f"{entry['commit']}) |")
    return "\n".join(lines) + "\n\nEach row's command: [docs/measured-scenes.json](docs/measured-scenes.json).\n"


def guide_seeds(registry: dict) -> pages.Seeds:
    """The fewest seeds any filed card rests on, and, where that is under ``pages.MIN_SEEDS``, which cards."""
    counts = {name: entry["chosen"].get("n_seeds", 1) for name, entry in registry.items()}
    fewest = min(counts.values(), default=pages.MIN_SEEDS)
    if fewest >= pages.MIN_SEEDS:
        return pages.Seeds(fewest)
    few = ", ".join(name for name, n in sorted(counts.items()) if n < pages.MIN_SEEDS)
    return pages.Seeds(fewest, f"{few} filed from fewer seeds: rerun the command of each "
                               "(docs/measured-scenes.json) to file it at --seeds 3")


def _update_docs(result: dict) -> None:
    path = hnn.tasks.repo_root() / REGISTRY
    registry = json.loads(path.read_text()) if path.exists() else {}
    meta = result["meta"]
    registry[result["scene"]] = {"chosen": result["chosen"], "naive": result["naive"], "units": meta["units"],
                                 "horizon": meta["horizon"], "command": meta["command"], "date": meta["date"],
                                 "commit": meta["commit"]}
    write_json(path, registry)
    print(f"updated {path}\nupdated {pages.update_section('measured-guide', guide(registry), guide_seeds(registry))}")


def run(args, argv: list[str], parser, inputs: Inputs | None = None) -> dict:
    """The study of ``args.data`` (parsed by scene_study's parser); a bad input is ``parser.error``.
    ``inputs``: the input ``measured_inputs.check`` read already (before torch loaded), if it did."""
    start = time.perf_counter()
    inputs = inputs or check(args, parser)
    data, columns, rec, held, energy = inputs.data, inputs.columns, inputs.rec, inputs.held, inputs.energy
    try:
        kinds = _kinds(columns)
    except (ValueError, FileNotFoundError) as err:
        parser.error(str(err))
    scene = Path(args.data).stem
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results") / f"scene-{scene}"
    steps = study.QUICK_STEPS if args.quick else None
    rows = _rows(columns, args.quick)
    cuts = quick_cuts(columns, args.seeds) if args.quick else []
    if cuts:
        commands.say_quick("scene_study --data", cuts)
    tic = time.perf_counter()
    seeds = list(range(args.seeds))
    # a rung without a width (a library's) trains at the widest cell on all the rows only
    grid = tuple(k for k in kinds if "+" not in k or k in scene_rungs.GRID_RUNGS)
    runs, _ = scene_common.train([(rows, seeds, steps, grid),
                                  ([max(rows, key=lambda r: r["cell"])], seeds, steps, tuple(set(kinds) - set(grid)))],
                                 out, args, fits=lambda task, kind: kind in kinds,
                                 then=lambda models: [plan.Stage("measure", models, "models on the held-out tails")],
                                 who=f"scene study of {Path(args.data).name} ({len(rec.t)} rows)")
    training = time.perf_counter() - tic
    tic = time.perf_counter()
    keys = [(row, kind, seed) for row in rows for kind in kinds for seed in seeds
            if isinstance(runs.get(f"{row['row']}/{kind}/seed{seed}"), Path)]
    measured, progress, ahead = [], sweep.Progress(len(keys)), plan.Ahead(len(keys))
    print(f"  {progress.tag()} measuring {progress.total} models on the held-out tails", flush=True)
    for row, kind, seed in keys:
        directory = runs[f"{row['row']}/{kind}/seed{seed}"]
        model = mm.Model(data, directory, json.loads((directory / "scale.json").read_text()), rec.state)
        cost = training_cost(TASK, model.args)
        measured.append({"kind": kind, "hidden_dim": row["cell"][0], "train_fraction": row["cell"][1], "seed": seed,
                         "params": model.params, "test_loss": model.metrics["test_loss"],
                         "train_seconds": cost["seconds"], "run": _in_checkout(directory),
                         **({"equation": found} if (found := mm.equation(model, rec)) else {}),
                         **mm.measure(model, held, energy)})
        print(f"  {progress.advance()} {kind:12s} width {row['cell'][0]:3d} fraction {row['cell'][1]:g} seed {seed}: "
              f"prediction error {measured[-1]['prediction_error']['median']:.4g} (naive {held.naive['median']:.4g})"
              + ahead.tag(progress.done), flush=True)
    chosen, card = _card(measured, held.naive, held.spread)
    units = "units of " + ", ".join(rec.q_names)
    result = {"scene": scene, "meta": {**provenance(), "command": "python analysis/scene_study.py " + " ".join(
        _portable(a) for a in argv), "quick": args.quick, "quick_cuts": cuts, "jobs": args.jobs, "seeds": seeds,
        "horizon": held.horizon, "units": units, "state": rec.state, "columns": columns, "data_sha256": rec.sha256,
        "notes": rec.notes,
        "assumes": data.ASSUMES if rec.state == "velocity" else None, "velocity_mismatch": velocity_mismatch(columns)},
        "rows": measured, "naive": held.naive, "chosen": chosen, "card": card,
        "seconds": {"training": training, "measure": time.perf_counter() - tic}}
    result["seconds"]["total"] = time.perf_counter() - start
    commands.publish(out, "scene", result, markdown(result))
    print(f"wrote {out / 'scene.json'}, {out / 'scene.md'}")
    if args.update_docs:
        _update_docs(result)
    sweep.exit_if_failed(runs)
    return result


def columns_of(text: str) -> list[str]:
    return hnn.load_task(TASK, "reader").names(text)


def _portable(arg: str) -> str:
    """An argument as the command line a reader can paste: paths inside the checkout made relative, others
    outside it as ``FILE`` (a file, e.g. ``--data``) or ``DIR`` (a folder, e.g. ``--out``), quoted."""
    path = Path(arg)
    if path.is_absolute():
        try:
            return str(path.relative_to(hnn.tasks.repo_root()))
        except ValueError:
            return "FILE" if path.is_file() else "DIR"
    return shlex.quote(arg)


def _in_checkout(directory: Path) -> str:
    """A run folder as the docs may name it: relative to the checkout when inside it (the docs commands write there), else as given."""
    root, directory = hnn.tasks.repo_root().resolve(), Path(directory).resolve()
    return str(directory.relative_to(root)) if directory.is_relative_to(root) else str(directory)
