"""The scene study's tables, built from its results dict (``scene_study.json``), never typed: every
kind per scene, the speed at equal accuracy, the grids, the scene cards, the D-HNN comparison
(``markdown``: ``scene_study.md`` and docs/scenes.md) and the README's model guide (``guide``).
"""
from __future__ import annotations

import hnn
from hnn_analysis.scenes import scene_common, scene_measure, scene_metrics as sm, scene_rungs
from hnn_analysis.pages import generated_by


def color(kind: str) -> str:
    """A model kind's plot colour, as its registration declares it (``hnn.kinds.ModelKind.color``); a fit's rung
    (``hnn+swim``) takes its kind's (its marker tells the fit: ``scene_rungs.marker``)."""
    spec = hnn.MODEL_KINDS.get(scene_rungs.kind_of(kind))
    return spec.color if spec else "k"


def _g(x, digits: int = 3) -> str:
    return "n/a" if x is None else f"{x:.{digits}g}"


def _pm(pair) -> str:
    if not pair:
        return "n/a"
    return f"{pair[0]:.3g}" + (f" ± {pair[1]:.2g}" if pair[1] else "")


def _main_metric(m: dict, key: str):
    return (m.get(key) or [None])[0]


def kind_table(results: dict) -> list[str]:
    seeds = results["meta"]["seeds"]
    many = len(seeds) > 1
    lines = [f"**Per scene and kind** (width 200, all the data; seed {seeds[0]}"
             + (f", and mean ± standard error over seeds {seeds}" if many else "") + "). Rollout error: the "
             "geometric mean over time of |x̂ − x| / (|x̂| + |x|) against the true system, averaged over "
             f"{results['meta'].get('starts', 8)} starts, over {results['meta'].get('horizon', 10)}x the training trajectories' "
             "length (a learned map: at every step of its data's dt over that horizon, against the truth at those "
             "times, and its energy MSE at every step over each protocol's span; pixels: decoded frames against rendered "
             "ones over the corrected protocol's 200 frames, 2x, no valid time: a decoded frame is never within 0.1; "
             "real: the measured test segment, 18 s, from its first state; there is no truth beyond it). Valid time: median first time that error exceeds 0.1 (= horizon: never); the truth "
             "column is when the true system itself, started 1e-4 away, leaves 0.1.", "",
             "| scene | model | params | test loss | energy MSE (paper protocol) | energy MSE (corrected) | "
             "rollout error | valid time / horizon | truth diverges after | train s |",
             "| --- | --- | ---: | --- | --- | --- | --- | --- | --- | ---: |"]
    for task, entry in results["scenes"].items():
        div = entry.get("divergence")
        for kind, measured in entry["kinds"].items():
            m = measured["per_seed"][str(seeds[0])] if str(seeds[0]) in measured["per_seed"] else \
                measured["per_seed"][seeds[0]]
            ro = m.get("rollout")
            cells = []
            for key in ("test_loss", "energy_mse_paper", "energy_mse_corrected"):
                s = measured.get(key + "_seeds")
                cells.append(_g(_main_metric(m, key)) + (f" ({_pm(s)})" if many and s else ""))
            err = measured.get("error_seeds")
            cells.append("n/a" if not ro else _g(ro["error"]) + (f" ({_pm(err)})" if many and err else ""))
            cells.append("n/a" if not ro or ro["valid_time"] is None else f"{ro['valid_time']:.3g} / {ro['horizon']:.3g}")
            cells.append("n/a" if not div else f"{div['divergence_time']:.3g}")
            lines.append(f"| {task} | {kind} | {m['params']} | " + " | ".join(cells)
                         + f" | {_g(_train_seconds(m, measured))} |")
    return lines + not_applicable_lines(results) + stopped_lines(results) + inseparable_lines(results)


def stopped_lines(results: dict) -> list[str]:
    """The rollouts a quick study stopped at their budget (``hnn.evaluation.rollout_budget``): energy protocols
    with no number above, and rollout errors whose stopped paths count as blown up."""
    lines = []
    for task, entry in results["scenes"].items():
        for kind, measured in entry["kinds"].items():
            for m in measured["per_seed"].values():
                for name, why in (m.get("energy_stopped") or {}).items():
                    lines.append(f"- {task}, {kind}, {name} protocol: {why}")
                if (m.get("rollout") or {}).get("stopped"):
                    lines.append(f"- {task}, {kind}, rollout error: {m['rollout']['stopped']} of its paths stopped "
                                 "over their budget, scored as blown up")
    return ["", "Rollouts stopped over their budget (--quick):", ""] + lines if lines else []


def not_applicable_lines(results: dict) -> list[str]:
    """The energy protocols that do not apply to a model (a learned map: one that rescales time), or whose rollout
    failed, and why: one line per reason, or per model where each seed's words differ (the state a rollout failed
    at), with its first seed's words and the count of seeds."""
    seen = {}
    for task, entry in results["scenes"].items():
        for kind, measured in entry["kinds"].items():
            whys = {}
            for m in measured["per_seed"].values():
                for name, why in (m.get("energy_not_applicable") or {}).items():
                    whys.setdefault(name, []).append(why)
            for name, found in whys.items():
                if len(set(found)) == 1:
                    seen.setdefault((task, name, found[0]), []).append(kind)
                else:
                    seen[(task, name, f"{found[0]} (the first of {len(found)} seeds)")] = [kind]
    if not seen:
        return []
    return ["", "Energy protocols that do not apply, or whose rollout failed (n/a above):", ""] + [
        f"- {task}, {name} protocol, {', '.join(dict.fromkeys(kinds))}: {why}" for (task, name, why), kinds in seen.items()]


def speed_table(results: dict) -> list[str]:
    starts = min(4, results["meta"].get("starts", 4))       # the speed study's starts: the first 4 of the scene's
    lines = ["**Speed at equal accuracy** (seed 0, width 200): the fastest `hnn.rollout` setting whose max relative "
             f"error over {starts} starts and the training trajectories' length stays within {sm.TARGET:g} of DOP853 "
             "rtol 1e-12 on the same field (float64), its median wall time, the fastest symplectic one and the "
             "fastest energy-preserving one (the discrete gradient, for a model that carries its H). "
             "Drift: max |E(t) − E(0)| / |E(0)| of the learned H (HNN, separable) or the true H (baseline) over "
             "the long run at that setting, on 2 starts; a run stops after "
             f"{scene_common.QUICK['drift_budget'] if results['meta']['quick'] else scene_common.DRIFT_BUDGET:g} s "
             "and says how far it got.", "",
             "| scene | model | fastest setting | s | drift (long run) | fastest symplectic | s | drift (long run) "
             "| fastest energy-preserving | s | drift (long run) |",
             "| --- | --- | --- | ---: | --- | --- | ---: | --- | --- | ---: | --- |"]
    for task, entry in results["scenes"].items():
        for kind, sp in entry.get("speed", {}).items():
            cells = []
            for key in scene_common.PICKS:
                pick = sp.get(key)
                if pick is None:
                    # a study saved before the energy-preserving pick existed has no such key
                    cells += ["none reached it" if key in sp else "not measured", "", ""]
                    continue
                d = pick.get("drift")
                drift = "" if d is None else (f"{d['drift']:.2g} over {d['periods_done']} {_unit(task)}"
                                              + (" (blew up)" if d["blew_up"] else ""))
                cells += [pick["setting"], f"{pick['seconds']:.3g}", drift]
            lines.append(f"| {task} | {kind} | " + " | ".join(cells) + " |")
    return lines


def _unit(task: str) -> str:
    return (hnn.task_spec(task).scene_study or {}).get("unit", "periods")


def grid_tables(results: dict) -> list[str]:
    lines = []
    for task, entry in results["scenes"].items():
        if not entry["grid"]:
            continue
        cells, spread = dict(entry["grid"]), dict(entry.get("grid_seeds") or {})
        for kind, measured in entry["kinds"].items():
            first = next(iter(measured["per_seed"].values()))
            cells[f"{kind}@200x1"] = first
            spread[f"{kind}@200x1"] = measured
        many = bool(entry.get("grid_seeds"))
        lines += ["", f"<details><summary>{task}: width x training fraction, every kind (seed 0"
                  + (", and mean ± standard error over seeds" if many else "") + ")</summary>", "",
                  "| model | width | fraction | params | test loss | energy MSE | rollout error | train s | "
                  "rollout s |", "| --- | ---: | ---: | ---: | --- | --- | --- | ---: | ---: |"]
        for key in sorted(cells, key=_cell_order):
            m, s = cells[key], spread.get(key, {})
            kind, cell = key.split("@")
            width, fraction = cell.split("x")
            name = "energy_mse_corrected" if m.get("energy_mse_corrected") else "energy_mse_paper"
            energy = m.get(name)
            ro = m.get("rollout") or {}
            lines.append(f"| {kind} | {width} | {fraction} | {m['params']} | {_g(m['test_loss'][0])} | "
                         f"{_over(energy[0] if energy else None, s.get(name + '_seeds') if many else None)} | "
                         f"{_over(ro.get('error'), s.get('error_seeds') if many else None)} | "
                         f"{_g(_train_seconds(m, s))} | {_g(ro.get('seconds'))} |")
        lines += ["", "</details>"]
    return lines


def _train_seconds(first: dict, seeds: dict) -> float | None:
    """A model's training seconds: the median of its seeds' timings (``seeds``: its ``_across`` numbers),
    else its first seed's."""
    return seeds.get("train_seconds_median") or scene_measure.cost_seconds(first)


def _over(value, seeds) -> str:
    """A first seed's number, and the mean ± standard error over seeds where given."""
    return _g(value) + (f" ({_pm(seeds)})" if seeds else "")


def _cell_order(key: str):
    kind, cell = key.split("@")
    width, fraction = cell.split("x")
    kinds = list(hnn.MODEL_KINDS)
    order = kinds.index(kind) if kind in kinds else len(kinds)
    return order, int(width), float(fraction)


def card_name(card: dict) -> str:
    """A scene card's model in words; a fallback card (no model within 2x of both bests) says so."""
    name = scene_rungs.describe(card["kind"], card["width"], card["fraction"])
    within = card.get("within", 1.0)
    if within > scene_common.CARD_FACTOR:
        return f"none within {scene_common.CARD_FACTOR:g}x of both bests; nearest: {name} ({within:.2g}x)"
    return name


def card_table(results: dict) -> list[str]:
    grid = results["meta"].get("grid_seeds", [0])
    gridded = [task for task, entry in results["scenes"].items() if entry.get("grid")]
    lines = ["**Scene cards**: the smallest model (fewest parameters, then the least data, then the cheapest to "
             "train) whose energy MSE (corrected protocol, else the paper's) and rollout error, each the mean over its seeds, both come "
             "within 2x of the best mean of its scene, over every kind and fit (the rungs of docs/fits.md)"
             + (f" and ({', '.join(gridded)}) every width and training fraction, the grid trained at "
                f"seed{'s' if len(grid) > 1 else ''} {', '.join(map(str, grid))}" if gridded else
                " at width 200 and all the data (no scene here has a width x data grid)")
             + " (where none does, the model nearest both bests: the smallest larger ratio, which the row gives). "
             "*Seeds cannot separate*: the smaller models whose mean is not within 2x of both bests but whose "
             "lowest seed on each error is, and whether the pick's highest seed on either error is over 2x; with one "
             "seed the card tests neither. Train s, here and "
             "below: the run's steps at the steps per second of that model alone on one thread, timed by this study "
             "over a short burst (not the run's recorded wall time, which depends on what else the machine did), the "
             "median over the model's seeds.", "",
             "| scene | enough | params | energy MSE (best) | rollout error (best) | train s | over seeds | "
             "seeds cannot separate | cheapest to train that is enough | a library that is enough |",
             "| --- | --- | ---: | --- | --- | ---: | --- | --- | --- | --- |"]
    for task, entry in results["scenes"].items():
        card = entry.get("card")
        if not card:
            lines.append(f"| {task} | no model measured on both | | | | | | | | |")
            continue
        seeds = card.get("seeds", {})
        over = ", ".join(f"{k.replace('_seeds', '')} {_pm(v)}" for k, v in seeds.items()
                         if k in ("error_seeds", "energy_mse_corrected_seeds", "energy_mse_paper_seeds"))
        lines.append(f"| {task} | {card_name(card)} | {card['params']} | {_g(card['energy'])} ({_g(card['best_energy'])}) | "
                     f"{_g(card['rollout'])} ({_g(card['best_rollout'])}) | {_g(card['train_seconds'])} | {over} | "
                     f"{unsettled(card)} | {cheapest_words(card)} | {library_words(card)} |")
    page = scene_common.PAGES[results["meta"].get("page", "scenes")]
    lines += [f"\nNot studied here: `{rung}`, {why}." for rung, why in page["left_out"].items()]
    return lines + ["", "*Cheapest to train that is enough*: of the models within 2x of both bests (the seeds' means), "
                    "the one whose seeds' median training seconds is least, Adam's kinds and the least-squares fits "
                    "(`--fit`: `+swim` a sampled layer, `+library` H as a sum of terms, `+sindy` pysindy's SINDy; "
                    "docs/fits.md) alike. *A library that is enough*: a library fit among those, with the equation "
                    "its first seed found (where a library is enough, it found the scene's equations to within the "
                    "card's 2x)."]


def cheapest_words(card: dict) -> str:
    """The card's model enough that trains fastest, in words (a card saved before it was chosen: not chosen)."""
    found = card.get("cheapest")
    if not found:
        # a measured card where no model predicts well enough (its "enough" False), or no model within 2x
        return "none is enough" if card.get("enough") is False else "none within 2x" if "cheapest" in card \
            else "not chosen"
    return f"{scene_rungs.describe(found['kind'], found['width'], found['fraction'])} ({_g(found['train_seconds'])} s)"


def library_words(card: dict) -> str:
    """The libraries enough, with their equations; 'none' where no library is (not measured on older cards)."""
    if "libraries" not in card:
        return "not measured"
    if card.get("enough") is False:
        return "none (no model is enough)"
    return "; ".join(f"{lib['kind']} ({_g(lib['train_seconds'])} s): `{lib['equation']}`" if lib.get("equation")
                     else lib["kind"] for lib in card["libraries"]) or "none"


def rollout_card_table(results: dict) -> list[str]:
    """Per scene, the cheapest rollout among the models its card accepts (``scene_stages.cheapest_rollout``)."""
    rows = [(task, entry["card"]["cheapest_rollout"]) for task, entry in results["scenes"].items()
            if (entry.get("card") or {}).get("cheapest_rollout")]
    if not rows:
        return []
    lines = ["**The cheapest rollout that is enough**: of the models whose mean energy MSE and rollout error come "
             "within 2x of their scene's best (the card's test, every kind and cell), the one whose rollout of the "
             "rollout-error metric takes the fewest seconds, the median over its seeds (a field: dopri5 rtol "
             f"{hnn.evaluation.ROLLOUT_SOLVER['rtol']:g} on {results['meta'].get('starts', 8)} starts in float64, one thread; a learned "
             "map: its own steps at its data's step over the same horizon). *Seeds cannot separate*: the other "
             "accepted models whose seeds' range of seconds overlaps the pick's.", "",
             "| scene | cheapest rollout that is enough | rollout s: median (range) | energy MSE / rollout error "
             "| seeds cannot separate |", "| --- | --- | --- | --- | --- |"]
    for task, c in rows:
        tied = ("one seed: not tested" if c["tied"] is None else ", ".join(c["tied"]) or "no other model")
        lines.append(f"| {task} | {scene_rungs.describe(c['kind'], c['width'], c['fraction'])} | "
                     f"{_g(c['rollout_seconds'])} ({_g(c['seconds_range'][0])}-{_g(c['seconds_range'][1])}, "
                     f"{c['n_seeds']} seed{'s' if c['n_seeds'] > 1 else ''}) | {_g(c['energy'])} / {_g(c['rollout'])} | "
                     f"{tied} |")
    return lines


def unsettled(card: dict) -> str:
    """What a card's seeds cannot settle, in words (a card saved before seeds were counted: not tested)."""
    if card.get("unsettled") is None:
        return "one seed: not tested" if card.get("n_seeds", 1) <= 1 else "not tested (no model within 2x)"
    words = ", ".join(card["unsettled"]) or "no smaller model"
    if card.get("pick_straddles"):
        words += "; some of the pick's own seeds are over 2x"
    return words


def inseparable_lines(results: dict) -> list[str]:
    """Per scene, the kinds (width 200, all the data) whose seeds overlap the best kind's, on each error."""
    lines = []
    for task, entry in results["scenes"].items():
        parts = [f"{what}: best {tie['best']}, the seeds cannot separate {', '.join(tie['tied']) or 'no other kind'}"
                 for what, tie in (entry.get("inseparable") or {}).items()]
        if parts:
            lines.append(f"- {task}: " + "; ".join(parts))
    if lines:
        lines = ["", "Which kinds the seeds cannot separate (width 200, all the data): for each error, the best kind "
                 "on the seeds' mean and the kinds whose seeds' range (min to max) overlaps the best's.", ""] + lines
    return lines


def dhnn_table(results: dict) -> list[str]:
    d = results.get("dhnn")
    if not d:
        return []
    lines = ["**The real pendulum, the D-HNN paper's protocol** (Sosanya & Greydanus 2022): their split (first 444 "
             "of 555 rows train, 111 test) and central-difference targets, their energy 2.4 (1 − cos q) + p², "
             "the rollout from the first test state with solve_ivp's defaults (RK45, rtol 1e-3). Ours: our "
             f"architectures (width 200) trained with `{' '.join(f'--{k} {v}' for k, v in d['config'].items() if k != 'name')}` (their rate, steps, batch "
             "and decay; their own MLP was a 256-unit residual net fed a zero time input, seed 42), seed 0, "
             "± over rows / points. Theirs: as their notebook prints it (one seed; the test ± is the spread of "
             "the last three logged test losses).", "",
             "| model | test vector-field MSE, ours | theirs | energy MSE, ours | theirs | state MSE along the rollout, "
             "ours |", "| --- | --- | --- | --- | --- | --- |"]
    for kind, ours in d["ours"].items():
        theirs = d["paper"].get(kind, {})
        lines.append(f"| {kind} | {_pm(ours['test_mse'])} | {_pm(theirs.get('test_mse'))} | "
                     f"{_pm(ours['energy_mse'])} | {_pm(theirs.get('energy_mse'))} | {_pm(ours['state_mse'])} |")
    return lines


def stamp(results: dict, wall: bool = True) -> str:
    """What made the numbers: one sitting's ``Generated by`` (with its wall times), or, for a page built from the
    record (``scene_record``) over several sittings, each sitting's, the oldest first, with the scenes it measured."""
    sittings = results["meta"].get("sittings") or [{**results["meta"], "seconds": results["seconds"], "scenes": None}]
    words = []
    for meta in sittings:
        sec = meta["seconds"]
        text = generated_by(meta, f"torch {meta['torch']}, {meta['cores']} cores, {meta['cpu']}, --jobs {meta['jobs']}")
        if len(sittings) > 1:
            text += f": {', '.join(meta['scenes'])}"
        if wall:
            text += (f". Wall time: training {sec.get('training', 0):.0f} s, measuring {sec.get('measure', 0):.0f} s, "
                     f"the chosen cells' seeds {sec.get('cards', 0):.0f} s, total {sec.get('total', 0):.0f} s")
        words.append(text)
    if len(words) == 1:
        return words[0]
    return (f"Measured over {len(words)} sittings, the oldest first, each scene's numbers from the last that "
            f"studied it (`--update-docs` keeps them in docs/{scene_common.PAGES[results['meta'].get('page', 'scenes')]['stem']}"
            "-record.json): " + "; ".join(words))


def markdown(results: dict) -> str:
    meta = results["meta"]
    lines = []
    if meta["quick"]:
        cut = meta.get("quick_cuts")
        lines += ["**QUICK smoke run: not the study's settings.**" + (f" Cut: {'; '.join(cut)}." if cut else ""), ""]
    lines += [stamp(results) + " (runs that reproduce.py or an earlier study saved with the same args are reused, "
              "not retrained).", ""]
    for part in (card_table, rollout_card_table, kind_table, speed_table, dhnn_table):
        block = part(results)
        if block:
            lines += block + [""]
    lines += ["**Capacity and data** (each scene's grid; energy MSE of the corrected protocol, else the paper's; "
              f"rollout s: the dopri5 rtol {hnn.evaluation.ROLLOUT_SOLVER['rtol']:g} rollout of the rollout-error metric; a learned "
              "map's: its own steps)"] + grid_tables(results)
    return "\n".join(lines) + "\n"


def guide(results: dict) -> str:
    """The README's model guide: each scene's card in one line, and where the rest is."""
    lines = ["| scene | a model that is enough (its seeds' mean within 2x of the best energy MSE and rollout error) | "
             "its energy MSE (corrected protocol, else the paper's) / rollout error | cheapest to train that is enough | "
             "seeds cannot separate |",
             "| --- | --- | --- | --- | --- |"]
    for task, entry in results["scenes"].items():
        card = entry.get("card")
        if card:
            lines.append(f"| {task} | {card_name(card)} | {_g(card['energy'])} / {_g(card['rollout'])} | "
                         f"{cheapest_words(card)} | {unsettled(card)} |")
    lines += ["", stamp(results, wall=False) + "; every kind, the grids, "
              "the speed at equal accuracy and the D-HNN comparison: [docs/scenes.md](docs/scenes.md)."]
    return "\n".join(lines) + "\n"
