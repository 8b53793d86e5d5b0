"""The verdict of a scene card of your own measurements, decided once (``decide``): every sentence of the
card (``sentences``) and every field the tables read (``chosen``: scene.json's ``chosen``, the README's rows)
come from that one ``Decision``, so a card cannot call one scene's models both enough and not.

A model is **enough** where its seeds' mean median prediction error is within ``CARD_FACTOR`` of the best
such mean, under ``BEATS_NAIVE`` of the naive extrapolation's error and under ``VALID_FRACTION`` of the
held-out positions' RMS spread. The two thresholds are on the error itself, so some model is enough exactly
where the best is: then the card picks the smallest model enough (parameters, then training rows, then
training seconds) and names the cheapest to train of those and the libraries among them; where the best is
not, none is, and the card says so of its smallest model within ``CARD_FACTOR`` and names no cheapest and no
library.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import hnn
from hnn_analysis.scenes import measured_metrics as mm, scene_common, scene_rungs

# a model is "enough" only if it also predicts: its error under this fraction of the naive extrapolation's
# and under ``measured_metrics.VALID_FRACTION`` of the tails' spread of positions (the valid time's threshold)
BEATS_NAIVE = 0.5
NEAR = 1.25            # "as good as": within this factor of the other's error
# a sine or cosine whose argument is more than a column (times a whole frequency): one of a scaled position
_SCALED_TRIG = re.compile(r"\b(?:sin|cos)\((?!(?:\d+ )?[A-Za-z_]\w*\))")


def models(rows: list[dict]) -> dict[tuple, dict]:
    """The measured rows (one a model and seed) by model, ``(kind, width, fraction)``: its seeds, their
    median prediction errors' ``(mean, min, max)`` as ``error``, and the means over seeds of the rest."""
    by = {}
    for r in rows:
        if r.get("prediction_error"):
            by.setdefault((r["kind"], r["hidden_dim"], r["train_fraction"]), []).append(r)
    out = {}
    for key, per_seed in by.items():
        def mean(get, per_seed=per_seed) -> float | None:
            spread = scene_common.seed_spread([get(r) for r in per_seed])
            return spread[0] if spread else None
        drift = per_seed[0].get("energy_drift")
        out[key] = {"kind": key[0], "hidden_dim": key[1], "train_fraction": key[2], "params": per_seed[0]["params"],
                    "seeds": sorted(r.get("seed", 0) for r in per_seed),
                    "error": scene_common.seed_spread([r["prediction_error"]["median"] for r in per_seed]),
                    "error_mean": mean(lambda r: r["prediction_error"]["mean"]),
                    "valid_time": mean(lambda r: r["valid_time"]["median"]),
                    "test_loss": mean(lambda r: r["test_loss"]), "train_seconds": mean(lambda r: r["train_seconds"]),
                    "rollout_seconds": mean(lambda r: r["rollout_seconds"]),
                    "energy_drift": ({"model": mean(lambda r: r["energy_drift"]["model"]),
                                      "measured": drift["measured"]} if drift else None),
                    "runs": [r["run"] for r in sorted(per_seed, key=lambda r: r.get("seed", 0))],
                    "equation": min(per_seed, key=lambda r: r.get("seed", 0)).get("equation")}
    return out


def error_range(m: dict) -> str:
    """``'0.5 (0.4-0.6)'``: a model's seeds' mean median error and, with several seeds, their range."""
    mean, low, high = m["error"]
    return f"{mean:.4g}" + (f" ({low:.3g}-{high:.3g})" if len(m["seeds"]) > 1 else "")


@dataclass(frozen=True)
class Decision:
    """What a card says, decided once. ``table``: ``models(rows)``; ``best``: the least mean median error;
    ``naive``, ``spread``: the naive extrapolation's median error and the tails' RMS spread of positions;
    ``within``: the models within ``CARD_FACTOR`` of the best; ``enough``: those also under both thresholds
    (empty exactly where the best is not); ``pick``: the smallest of ``enough``, else of ``within``;
    ``cheapest``: the one of ``enough`` that trains fastest (None where none is enough); ``libraries``:
    the library rungs of ``enough``; ``unsettled``: the smaller models whose mean fails the pick's test but
    whose lowest seed passes it, and ``straddles``: whether the pick's highest seed fails it (both None
    with one seed, where nothing is tested)."""
    table: dict
    best: float
    naive: float
    spread: float
    within: tuple
    enough: tuple
    pick: tuple
    cheapest: tuple | None
    libraries: tuple
    unsettled: tuple | None
    straddles: bool | None

    @property
    def is_enough(self) -> bool:
        return bool(self.enough)

    def short(self, error: float, thresholds: bool | None = None) -> list[str]:
        """Why a median error ``error`` fails the pick's test, one phrase each (empty: it passes). ``thresholds``:
        whether the test holds the two thresholds beside the 2x (default: where some model is enough)."""
        thresholds = self.is_enough if thresholds is None else thresholds
        out = [f"over {scene_common.CARD_FACTOR:g}x of the best"] if error > scene_common.CARD_FACTOR * self.best else []
        if thresholds:
            out += self.thresholds(error)
        return out

    def thresholds(self, error: float) -> list[str]:
        """Which of the two thresholds a median error misses, one phrase each."""
        out = [f"not under {BEATS_NAIVE:g} of the naive one"] if _ratio(error, self.naive) > BEATS_NAIVE else []
        return out + ([f"over {mm.VALID_FRACTION:g} of the spread"] if _ratio(error, self.spread) > mm.VALID_FRACTION
                      else [])


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else math.inf


def decide(rows: list[dict], naive: dict, spread: float) -> Decision | None:
    """The card's ``Decision`` from the measured ``rows`` (one a model and seed), the ``naive`` extrapolation's
    errors and the tails' RMS ``spread`` of positions; None where no model was measured."""
    table = models(rows)
    if not table:
        return None
    best = min(m["error"][0] for m in table.values())
    within = tuple(k for k, m in table.items() if m["error"][0] <= scene_common.CARD_FACTOR * best)
    probe = Decision(table, best, naive["median"], spread, within, (), within[0], None, (), None, None)
    enough = tuple(k for k in within if not probe.thresholds(table[k]["error"][0]))

    def size(key) -> tuple:
        # fewest parameters, then the fewest training rows (both exact), then the fastest to train (a timing)
        return table[key]["params"], key[2], table[key]["train_seconds"] or 0.0

    def seconds(key) -> float:
        return table[key]["train_seconds"] or math.inf

    pick = min(enough or within, key=size)
    decided = Decision(table, best, naive["median"], spread, within, enough, pick,
                       min(enough, key=lambda k: (seconds(k), k[1])) if enough else None,
                       tuple(k for k in sorted(enough, key=seconds) if scene_rungs.is_library(k[0])), None, None)
    if len(table[pick]["seeds"]) < 2:
        return decided
    unsettled = tuple(k for k in sorted(table, key=size) if size(k) < size(pick) and len(table[k]["seeds"]) > 1
                      and decided.short(table[k]["error"][0]) and not decided.short(table[k]["error"][1]))
    return replace(decided, unsettled=unsettled, straddles=bool(decided.short(table[pick]["error"][2])))


def chosen(d: Decision) -> dict:
    """scene.json's ``chosen``, which the README's rows and the tables read: the pick and its numbers,
    ``enough``, ``cheapest`` (None where none is enough), ``libraries``, ``unsettled`` and ``pick_straddles``."""
    m, table = d.table[d.pick], d.table
    out = {key: m[key] for key in ("kind", "hidden_dim", "train_fraction", "params", "train_seconds",
                                   "rollout_seconds", "valid_time", "energy_drift", "seeds")}
    c = d.cheapest
    out.update({"cheapest": None if c is None else {"kind": c[0], "width": c[1], "fraction": c[2],
                                                    "train_seconds": table[c]["train_seconds"]},
                "libraries": [{"kind": k[0], "fraction": k[2], "train_seconds": table[k]["train_seconds"],
                               "equation": table[k]["equation"]} for k in d.libraries],
                "n_seeds": len(m["seeds"]), "test_loss": m["test_loss"], "run": m["runs"][0], "runs": m["runs"],
                "enough": d.is_enough, "of_naive": _ratio(m["error"][0], d.naive),
                "of_spread": _ratio(m["error"][0], d.spread),
                # as scene_stages.scene_card words them: None where one seed tests nothing
                "unsettled": None if d.unsettled is None else [f"{k[0]}, width {k[1]}, {k[2]:g} of the data"
                                                               for k in d.unsettled],
                "pick_straddles": d.straddles,
                "prediction_error": {"median": m["error"][0], "min": m["error"][1], "max": m["error"][2],
                                     "mean": m["error_mean"]}})
    return out


def sentences(d: Decision) -> list[str]:
    """The card's sentences, each read from ``d``: the verdict on the pick, what the seeds cannot settle, the
    cheapest enough and the libraries enough (or that none is), and what the kinds' structure bought."""
    m, factor = d.table[d.pick], scene_common.CARD_FACTOR
    n, err = len(m["seeds"]), m["error"][0]
    seeds = f"mean over {n} seeds" if n > 1 else "one seed"
    model = (f"{scene_rungs.describe(m['kind'], m['hidden_dim'], m['train_fraction'])} ("
             f"{m['params']} parameters, {m['train_seconds']:.3g} s to train on one thread)")
    numbers = (f"its median prediction error ({seeds}) {error_range(m)} is within {factor:g}x of the best "
               f"({d.best:.4g}), {_ratio(err, d.naive):.2g}x the naive extrapolation's ({d.naive:.4g}) and "
               f"{_ratio(err, d.spread):.2g} of the held-out positions' RMS spread ({d.spread:.4g})")
    said = [f"{model} is enough: {numbers}." if d.is_enough else
            f"{model} is the smallest model within {factor:g}x of the best, but NOT enough: {numbers}; that is "
            f"{' and '.join(d.thresholds(err))}: no kind predicts this scene well at this horizon."]
    if n > 1:
        if d.unsettled:
            reasons = " and ".join(dict.fromkeys(r for k in d.unsettled for r in d.short(d.table[k]["error"][0])))
            said.append(f"The seeds cannot separate from it the smaller "
                        f"{', '.join(f'{k[0]} (width {k[1]}, {k[2]:g})' for k in d.unsettled)}: their means are "
                        f"{reasons}, their lowest seeds within it.")
        if d.straddles:
            said.append(f"Its highest seed ({m['error'][2]:.3g}) is {' and '.join(d.short(m['error'][2]))}: "
                        "the seeds do not settle that it is the one to pick.")
    else:
        said.append("One seed: whether seeds separate these models was not tested (--seeds 3 tests it).")
    return said + _cheapest_and_libraries(d) + _structure(d)


def _cheapest_and_libraries(d: Decision) -> list[str]:
    """The model enough that trains fastest, and the libraries (ours, SINDy's) enough with the equations they
    found; where none is enough, that there is neither."""
    libraries = [k for k in d.table if scene_rungs.is_library(k[0])]
    if not d.is_enough:
        return ["No model predicts this scene well enough to name the cheapest to train"
                + (", nor a library's equations." if libraries else ".")]
    c = d.table[d.cheapest]
    said = [f"The cheapest to train that is enough: {scene_rungs.describe(c['kind'], c['hidden_dim'], c['train_fraction'])}"
            f", {c['train_seconds']:.3g} s on one thread."]
    if d.libraries:
        equations = [d.table[k]["equation"] or "" for k in d.libraries]
        said.append("A library is enough here: it found the equations " + "; ".join(
            f"{k[0]} `{e}`" for k, e in zip(d.libraries, equations)) + " (in your columns and units).")
        if any(_SCALED_TRIG.search(e) for e in equations):
            said.append("A sine or cosine there reads the study's scaled position (q - q0) / a (the library's terms "
                        "are of the scaled coordinates), written out in your units: cos(q / a - q0 / a).")
    elif libraries:
        near = d.table[min(libraries, key=lambda k: d.table[k]["error"][0])]
        said.append(f"No library (hnn+library, baseline+sindy) is enough here: the nearest, {near['kind']} "
                    f"{error_range(near)}, is {' and '.join(d.short(near['error'][0]))}: the equations are not among "
                    "its terms, or the data's noise hides them.")
    return said


def _structure(d: Decision) -> list[str]:
    """Whether the energy-conserving kinds helped or hurt, and the plain baseline against the structured kinds."""
    said = []

    def best_of(kinds) -> dict | None:
        pool = [m for m in d.table.values() if m["kind"] in kinds]
        return min(pool, key=lambda m: m["error"][0]) if pool else None

    def compare(a: dict, b: dict, verdict: str, tie: str) -> str:
        numbers = f"best {a['kind']} {error_range(a)} against best {b['kind']} {error_range(b)}."
        separate = (len(a["seeds"]) < 2 or len(b["seeds"]) < 2
                    or not scene_common.seeds_overlap(a["error"], b["error"]))
        return f"{verdict}: {numbers}" if separate else f"{tie} cannot be told apart on these seeds: {numbers}"

    # the kinds and the fits' rungs of them, by what their kind declares
    labels = {m["kind"] for m in d.table.values()}
    conserving = best_of([k for k in labels if hnn.MODEL_KINDS[scene_rungs.kind_of(k)].conservative])
    others = best_of([k for k in labels if not hnn.MODEL_KINDS[scene_rungs.kind_of(k)].conservative])
    if conserving and others:
        a, b = conserving["error"][0], others["error"][0]
        verdict = "helped" if a * NEAR < b else "hurt" if b * NEAR < a else "neither helped nor hurt (within 25%)"
        said.append(compare(conserving, others, f"The energy-conserving kinds {verdict}",
                            "The energy-conserving kinds and the others"))
    baseline, structured = best_of(["baseline"]), best_of([k for k in hnn.MODEL_KINDS if k != "baseline"])
    if baseline and structured:
        a, b = baseline["error"][0], structured["error"][0]
        word = "better than" if a * NEAR < b else "as good as" if a <= NEAR * b else "worse than"
        said.append(compare(baseline, structured, f"The plain baseline is {word} the structured kinds here",
                            "The plain baseline and the structured kinds"))
    return said
