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
training (``hnn_analysis.training_cost``, one thread) and rollout seconds. The card picks the
smallest model (parameters, then training seconds) within ``CARD_FACTOR`` of the best median
prediction error (ties: fewer training rows). Writes ``<out>/scene.json`` and ``<out>/scene.md``; ``--update-docs`` files the
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
from hnn_analysis import commands, pages
from hnn import sweep
from hnn_analysis.paper import study
from hnn_analysis.provenance import provenance
from hnn_analysis.scenes import measured_metrics as mm, scene_common
from hnn_analysis.training_cost import training_cost

TASK = "measured"
WIDTHS, FRACTIONS = (32, 200), (0.5, 1.0)
QUICK_WIDTHS, QUICK_FRACTIONS = (64,), (1.0,)
COLUMNS = ("data", "time", "q", "v", "p", "trial", "periodic", "dxdt", "test_fraction", "max_gap")
REGISTRY = "docs/measured-scenes.json"      # the cards --update-docs files, by data file name
NEAR = 1.25            # "as good as": within this factor of the other's error


def add_flags(parser) -> None:
    """The column flags of experiment-measured/train.py, and the study's own."""
    defaults = hnn.load_task(TASK, "train").Config
    group = parser.add_argument_group("your own measurements (the study of one file instead of the shipped scenes)")
    for name in COLUMNS:
        meta = hnn.cli.field_meta(defaults, name)
        group.add_argument(f"--{name}", type=meta.get("parse") or str, default=getattr(defaults, name),
                           help=meta.get("help"))
    group.add_argument("--horizon", type=hnn.cli.positive_float, default=None,
                       help="seconds ahead of the prediction error (default: a tenth of the shortest held-out tail)")
    group.add_argument("--energy", default=None,
                       help="an energy of your columns as a numpy expression (e.g. '0.5*v**2 + 2*x**2'): its drift")


def _kinds(columns: dict) -> list[str]:
    """The kinds that fit these coordinates: each built on the data and handed to its objective's checks."""
    config = hnn.tasks.task_config(TASK, columns)
    dataset = config.dataset()
    kinds = []
    for kind in hnn.cli.model_choices(type(config)):
        if not hnn.MODEL_KINDS[kind].studied:
            continue
        try:
            run = hnn.tasks.task_config(TASK, {**columns, "model": kind, "hidden_dim": 4})
            objective = run.make_objective()
            saved = {**run.to_dict(), "kind": run.kind}
            objective.train_options(hnn.kinds.model_from_args(saved), hnn.specs.run_specs(saved).objective,
                                    objective.prepare(dataset))
        except (ValueError, KeyError) as err:      # refused by its checks, or it needs what the file lacks
            print(f"  {kind}: does not fit these coordinates ({err})", flush=True)
            continue
        kinds.append(kind)
    return kinds


def quick_cuts(columns: dict) -> list[str]:
    """What ``--quick`` cuts from the study of a file, one phrase each, as ``run`` prints them."""
    steps = hnn.tasks.task_config(TASK, columns).total_steps
    return [f"{study.QUICK_STEPS} training steps a model of {steps}",
            f"grid: widths {', '.join(map(str, QUICK_WIDTHS))} x fractions {', '.join(map(str, QUICK_FRACTIONS))} "
            f"of {', '.join(map(str, WIDTHS))} x {', '.join(map(str, FRACTIONS))}"]


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


def _card(rows: list[dict], naive: dict) -> tuple[dict | None, list[str]]:
    """The chosen row (smallest within ``CARD_FACTOR`` of the best median) and the card's sentences."""
    measured = [r for r in rows if r.get("prediction_error")]
    if not measured:
        return None, ["no model was measured"]
    best = min(r["prediction_error"]["median"] for r in measured)
    ok = [r for r in measured if r["prediction_error"]["median"] <= scene_common.CARD_FACTOR * best]
    # fewest parameters, then the fewest training rows (both exact), then the fastest to train (a timing)
    chosen = min(ok, key=lambda r: (r["params"], r["train_fraction"], r["train_seconds"] or 0.0))
    err = chosen["prediction_error"]["median"]
    ratio = err / naive["median"] if naive["median"] > 0 else float("inf")
    said = [f"{chosen['kind']} (width {chosen['hidden_dim']}, {chosen['train_fraction']:g} of the training rows, "
            f"{chosen['params']} parameters, {chosen['train_seconds']:.3g} s to train on one thread) is enough: its "
            f"median prediction error {err:.4g} is within {scene_common.CARD_FACTOR:g}x of the best ({best:.4g}) "
            f"and {ratio:.2f}x the naive extrapolation's ({naive['median']:.4g})"
            + ("." if ratio <= 0.5 else "; that is NOT under half the naive one: no kind predicts this scene well.")]

    def best_of(kinds) -> dict | None:
        pool = [r for r in measured if r["kind"] in kinds]
        return min(pool, key=lambda r: r["prediction_error"]["median"]) if pool else None

    conserving = best_of([k for k in hnn.MODEL_KINDS if hnn.MODEL_KINDS[k].conservative])
    others = best_of([k for k in hnn.MODEL_KINDS if not hnn.MODEL_KINDS[k].conservative])
    if conserving and others:
        a, b = conserving["prediction_error"]["median"], others["prediction_error"]["median"]
        verdict = "helped" if a * NEAR < b else "hurt" if b * NEAR < a else "neither helped nor hurt (within 25%)"
        said.append(f"The energy-conserving kinds {verdict}: best {conserving['kind']} {a:.4g} against best "
                    f"{others['kind']} {b:.4g}.")
    baseline, structured = best_of(["baseline"]), best_of([k for k in hnn.MODEL_KINDS if k != "baseline"])
    if baseline and structured:
        a, b = baseline["prediction_error"]["median"], structured["prediction_error"]["median"]
        word = "better than" if a * NEAR < b else "as good as" if a <= NEAR * b else "worse than"
        said.append(f"The plain baseline is {word} the structured kinds "
                    f"here ({a:.4g} against {structured['kind']} {b:.4g}).")
    return chosen, said


def markdown(result: dict) -> str:
    meta, naive = result["meta"], result["naive"]
    lines = []
    if meta["quick"]:
        cut = meta.get("quick_cuts")
        lines += [f"**QUICK smoke run ({study.QUICK_STEPS} steps per model): not the study's settings.**"
                  + (f" Cut: {'; '.join(cut)}." if cut else ""), ""]
    lines += [f"# Scene card: {result['scene']}", "",
              f"Generated by `{meta['command']}` on {meta['date']} (commit {meta['commit']}, torch {meta['torch']}, "
              f"{meta['cores']} cores, --jobs {meta['jobs']}). Wall time: training {result['seconds']['training']:.0f} s, "
              f"measuring {result['seconds']['measure']:.0f} s, total {result['seconds']['total']:.0f} s.", "",
              *result["card"], "",
              f"Prediction error: from each of {naive['starts']} held-out samples with a measured sample "
              f"{meta['horizon']:.4g} s later, the norm of the position error there ({meta['units']}; angles wrapped), "
              f"median / mean over starts. Naive: q(t) + h v(t): {naive['median']:.4g} / {naive['mean']:.4g}. Valid "
              f"time: median first time the error exceeds {mm.VALID_FRACTION:g} of the tail's RMS spread (s). Test "
              "loss: the derivative MSE on the scaled states (dimensionless). Train s: one thread, controlled.", ""]
    if meta.get("assumes"):
        lines += [f"Note: {meta['assumes']}.", ""]
    lines += [line for note in meta.get("notes") or [] for line in (f"Note: {note}.", "")]
    if meta.get("velocity_mismatch"):
        lines += ["Velocity columns against the finite-difference derivatives of the positions, RMS(dq/dt - v) / "
                  "RMS(v) on the training rows: " + ", ".join(f"{name} {m:.3g}" for name, m in zip(
                      columns_of(meta["columns"]["q"]), meta["velocity_mismatch"])) + " (kinds that take dq/dt = v "
                  "exactly, second_order and mechanical, and hnn reading v as p, inherit this gap; the baseline learns "
                  "dq/dt freely).", ""]
    energy = any("energy_drift" in r for r in result["rows"])
    lines += ["| model | width | fraction | params | prediction error median / mean | valid time s | test loss | "
              + ("energy drift (measured) | " if energy else "") + "train s | rollout s |",
              "| --- | ---: | ---: | ---: | --- | ---: | --- | " + ("--- | " if energy else "") + "---: | ---: |"]
    for r in sorted(result["rows"], key=lambda r: r["prediction_error"]["median"]):
        pe, drift = r["prediction_error"], r.get("energy_drift")
        lines.append(f"| {r['kind']} | {r['hidden_dim']} | {r['train_fraction']:g} | {r['params']} | "
                     f"{pe['median']:.4g} / {pe['mean']:.4g} | {r['valid_time']['median']:.3g} | {r['test_loss']:.3g} | "
                     + (f"{drift['model']:.3g} ({drift['measured']:.3g}) | " if drift else "")
                     + f"{r['train_seconds']:.3g} | {r['rollout_seconds']:.3g} |")
    # the naive extrapolation as the table's last row: its error, and an empty cell for every other column
    lines.append(f"| naive q + h v | | | | {naive['median']:.4g} / {naive['mean']:.4g} | | | "
                 + ("| " if energy else "") + "| |")
    return "\n".join(lines) + "\n"


def guide(registry: dict) -> str:
    """The README's rows of measured scenes, from the filed cards (each card's command is in
    docs/measured-scenes.json, and the shipped scenes' commands in docs/measured.md)."""
    lines = ["| measured scene | a model that is enough (within 2x of the best prediction error) | its median prediction "
             "error, the naive extrapolation's | horizon | train s | made |",
             "| --- | --- | --- | ---: | ---: | --- |"]
    for name, entry in sorted(registry.items()):
        c = entry["chosen"]
        lines.append(f"| {name} | {c['kind']}, width {c['hidden_dim']}, {c['train_fraction']:g} of the data | "
                     f"{c['prediction_error']['median']:.3g}, naive {entry['naive']['median']:.3g} "
                     f"({entry['units']}) | {entry['horizon']:.3g} s | {c['train_seconds']:.3g} | "
                     f"({entry['date']}, commit {entry['commit']}) |")
    return "\n".join(lines) + "\n\nEach row's command: [docs/measured-scenes.json](docs/measured-scenes.json).\n"


def _update_docs(result: dict) -> None:
    path = hnn.tasks.repo_root() / REGISTRY
    registry = json.loads(path.read_text()) if path.exists() else {}
    meta = result["meta"]
    registry[result["scene"]] = {"chosen": result["chosen"], "naive": result["naive"], "units": meta["units"],
                                 "horizon": meta["horizon"], "command": meta["command"], "date": meta["date"],
                                 "commit": meta["commit"]}
    write_json(path, registry)
    seeds = pages.Seeds(1, "the measured study trains each kind once (seed 0) on the user's data; it takes no --seeds yet")
    print(f"updated {path}\nupdated {pages.update_section('measured-guide', guide(registry), seeds)}")


def run(args, argv: list[str], parser) -> dict:
    """The study of ``args.data`` (parsed by scene_study's parser); a bad input is ``parser.error``."""
    start = time.perf_counter()
    data = hnn.load_task(TASK)
    columns = {name: getattr(args, name) for name in COLUMNS}
    columns["data"] = str(Path(args.data).expanduser().resolve()) if args.data else ""
    try:
        hnn.tasks.task_config(TASK, columns)
        rec = data.load(*(columns[k] for k in ("data", "time", "q", "v", "p", "trial", "periodic", "dxdt")))
        for note in rec.notes:
            print(f"note: {note}", flush=True)
        held = mm.Heldout(data, rec, args.test_fraction, args.horizon, args.max_gap)
        energy = mm.energy_function(args.energy, rec)
        kinds = _kinds(columns)
    except (ValueError, FileNotFoundError) as err:
        parser.error(str(err))
    scene = Path(args.data).stem
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results") / f"scene-{scene}"
    steps = study.QUICK_STEPS if args.quick else None
    rows = _rows(columns, args.quick)
    cuts = quick_cuts(columns) if args.quick else []
    if cuts:
        commands.say_quick("scene_study --data", cuts)
    tic = time.perf_counter()
    runs, _ = scene_common.train([(rows, [0], steps, tuple(kinds))], out, args, fits=lambda task, kind: kind in kinds)
    training = time.perf_counter() - tic
    tic = time.perf_counter()
    measured, progress = [], sweep.Progress(sum(isinstance(runs.get(f"{row['row']}/{kind}/seed0"), Path)
                                                for row in rows for kind in kinds))
    print(f"  {progress.tag()} measuring {progress.total} models on the held-out tails", flush=True)
    for row in rows:
        for kind in kinds:
            directory = runs.get(f"{row['row']}/{kind}/seed0")
            if not isinstance(directory, Path):
                continue
            model = mm.Model(data, directory, json.loads((directory / "scale.json").read_text()), rec.state)
            cost = training_cost(TASK, model.args)
            measured.append({"kind": kind, "hidden_dim": row["cell"][0], "train_fraction": row["cell"][1],
                             "params": model.params, "test_loss": model.metrics["test_loss"],
                             "train_seconds": cost["seconds"], "run": _in_checkout(directory),
                             **mm.measure(model, held, energy)})
            print(f"  {progress.advance()} {kind:12s} width {row['cell'][0]:3d} fraction {row['cell'][1]:g}: prediction error "
                  f"{measured[-1]['prediction_error']['median']:.4g} (naive {held.naive['median']:.4g})", flush=True)
    chosen, card = _card(measured, held.naive)
    units = "units of " + ", ".join(rec.q_names)
    result = {"scene": scene, "meta": {**provenance(), "command": "python analysis/scene_study.py " + " ".join(
        _portable(a) for a in argv), "quick": args.quick, "quick_cuts": cuts, "jobs": args.jobs,
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
