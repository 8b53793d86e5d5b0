"""What one run's training costs under control: the steps per second of that model alone on one
thread over short bursts (a fresh model of its config on its data, after a few warm-up steps),
times the run's steps; for a least-squares fit (``--fit``), its whole solve on one thread, the
fastest of a few. The recorded wall time of a run says more about what else the machine did
while it trained; the scene study, the measured study and the peers' table compare kinds by this.

    cost = training_cost("spring", hnn.load_run(folder)[1])    # {"steps_per_s", "steps", "seconds"}
"""
from __future__ import annotations

import copy

import numpy as np

import hnn
from hnn.threads import torch_threads

BURST_SECONDS = 0.15     # the timed bursts of a training-cost measurement last about this long
BURSTS = 3               # ... in this many bursts (the fastest counts)
BURST_STEPS = (5, 400)   # ... of at least / at most this many steps each
_DATASETS: dict = {}     # this process's datasets of training-cost measurements, by dataset key


def training_cost(task: str, args: dict, bursts: int = BURSTS, burst_seconds: float = BURST_SECONDS) -> dict:
    """``{"steps_per_s", "steps", "seconds"}``: one thread's training steps per second of the run
    with saved ``args`` (a fresh model of its config on its data, after a few warm-up steps; the
    fastest of ``bursts`` bursts of about ``burst_seconds`` in all), and ``seconds`` = its ``total_steps + 1``
    steps at that rate. A plan's estimate takes one short burst (``analysis/plan.py``)."""
    config = hnn.tasks.task_config(task, args)
    data_key = config.dataset_key()
    if data_key not in _DATASETS:
        _DATASETS[data_key] = config.dataset()
    # the run's own model, rows, units, loss and loop settings (its optimizer, schedule, clipping too)
    prep = hnn.prepare(config, _DATASETS[data_key])
    if config.fit != "adam":
        return _fit_cost(config, prep)
    model = prep.canonical_model
    options = prep.train_kwargs(print_every=10 ** 9, verbose=False, progress=False, checkpoint=None)
    start = copy.deepcopy(model.state_dict())

    def burst(steps: int) -> float:
        # every burst from the same start: a fresh Adam's first steps are full-size, and bursts chained
        # from one model drove a chain model's weights to divergence
        model.load_state_dict(start)
        return hnn.train(model, prep.x, prep.y, **{**options, "total_steps": steps - 1})["seconds"]

    with torch_threads(1):
        per_step = burst(3) / 3                                           # one-time setup, a first rate
        steps = int(np.clip(burst_seconds / bursts / max(per_step, 1e-6), *BURST_STEPS))
        # the fastest of a few bursts: what the model's steps cost when nothing else interferes
        rate = max(steps / burst(steps) for _ in range(bursts))
    return {"steps_per_s": rate, "steps": config.total_steps + 1, "seconds": (config.total_steps + 1) / rate}


def _fit_cost(config, prep) -> dict:
    """``{"steps_per_s": None, "steps": 1, "seconds"}`` of a least-squares fit: its solve (the neurons'
    draw, the design, the QR, the threshold) on a fresh model of ``saved``'s args on one thread, the
    fastest of up to ``BURSTS`` solves within about a second (the recorded wall time of a fit
    inside a sweep shares the box with the sweep's other worker)."""
    seconds = []
    with torch_threads(1):
        while len(seconds) < BURSTS and sum(seconds) < 1.0:
            model = hnn.kinds.model_from_spec(prep.specs.model, config.device)
            seconds.append(hnn.fits.solve(model, prep.x, prep.y, **prep.specs.fit.solve_kwargs(), progress=False,
                                          loss_weights=prep.options.loss_weights)["seconds"])
    return {"steps_per_s": None, "steps": 1, "seconds": min(seconds)}
