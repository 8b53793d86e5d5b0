"""One scene of the scene study: its settings (each task's ``TaskSpec.scene_study``), the model
kinds and the fits' rungs (``scene_rungs``) that fit it, the training of its rows (one sweep), its truth (``Scene``: start states, the true
trajectories, the time over which the truth itself diverges) and the measurements of one model on
it (losses, energy MSE, rollout error, speed at equal accuracy, drift). ``scene_study`` (the
command), ``scene_measure`` (its worker processes) and ``measured_study`` (your own file) build
on it."""
from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.sweeps import sweep
from hnn_analysis import plan
from hnn_analysis.paper import registry, study
from hnn_analysis.scenes import scene_metrics as sm, scene_rungs
from hnn_analysis.integrator_study import settings

HORIZON = 10               # the rollout metrics' horizon, in training-trajectory lengths
STARTS = 8                 # start states of the rollout metrics
SEEDS = 3                  # the full study's --seeds: the per-kind rows, the grid (unless --grid-seeds), --data's models
CARD_FACTOR = 2.0          # a scene card's model is within this factor of the best on both errors
DRIFT_BUDGET = 15.0        # seconds of one long drift run before it stops and says how far it got
# --quick (a smoke run within its budget, commands.QUICK_BUDGETS): what each measurement does instead
QUICK = {"starts": 2, "horizon": HORIZON // 2, "points": 50, "drift_periods": 3, "drift_budget": 0.5, "timings": 1}
FULL = {"starts": STARTS, "horizon": HORIZON, "points": 100, "drift_periods": None, "drift_budget": DRIFT_BUDGET,
        "timings": 3}


def seed_spread(values: list) -> tuple[float, float, float] | None:
    """(mean, min, max) of the seeds' values that were measured (None skipped), or None if none was."""
    values = [v for v in values if v is not None]
    return (sum(values) / len(values), min(values), max(values)) if values else None


def seeds_overlap(a: tuple[float, float, float], b: tuple[float, float, float]) -> bool:
    """Whether two models' seeds, each as ``seed_spread``'s (mean, min, max), overlap in range: then
    the seeds cannot separate them."""
    return a[1] <= b[2] and b[1] <= a[2]


# the pages of the scene cards, by the ``page`` each scene declares (``TaskSpec.scene_study``; absent: "scenes"): a
# page shows one study of its scenes, whole: the sections ``--update-docs`` writes, and the names of its results
# (``<out>/<stem>.json``) and of its Pareto figure, so that one page's study never overwrites another's
# (``left_out``: the fits' rungs a page's scenes do not study, and why)
PAGES = {"scenes": {"sections": ("scenes", "model-guide"), "stem": "scene_study", "figure": "scenes-pareto.png",
                    "left_out": {}},
         "bodies": {"sections": ("bodies-scenes",), "stem": "scene_study_bodies", "figure": "bodies-pareto.png",
                    "left_out": {"baseline+sindy": "SINDy's cubic library of dx/dt on the 32 columns of 8 bodies has 6545 "
                                                   "terms: one fit on gravity's training rows ran over 10 minutes on one "
                                                   "thread without finishing, where the pair kind's library of one "
                                                   "distance takes under a second"}}}


def scenes(page: str | None = "scenes") -> list[str]:
    """The tasks of this checkout whose ``TaskSpec`` declares ``scene_study`` and whose ``page`` is ``page``
    (default the paper's scenes, docs/scenes.md; None: every page's)."""
    return [task for task in hnn.available_tasks() if hnn.task_spec(task).scene_study is not None
            and (page is None or page_of(task) == page)]


def page_of(task: str) -> str:
    """The page (``PAGES``) of ``task``'s scene card."""
    return (hnn.task_spec(task).scene_study or {}).get("page", "scenes")


def scene_settings(task: str) -> dict:
    """``task``'s scene-study settings (``TaskSpec.scene_study``: T, dts, the drift, grid)."""
    return dict(hnn.task_spec(task).scene_study or {})


def kinds() -> tuple[str, ...]:
    """The model kinds the study measures: every registered kind a task's --model takes (hnn.MODEL_KINDS)
    that its row marks ``studied``."""
    return tuple(kind for kind in hnn.cli.model_choices() if hnn.MODEL_KINDS[kind].studied)


def task_kinds(task: str) -> list[str]:
    """The model kinds of ``task``: the kinds its ``--model`` takes that can fit its states."""
    return [kind for kind in study.row_models(task, kinds()) if _fits(task, kind)]


def task_rungs(task: str, rungs=scene_rungs.RUNGS) -> list[str]:
    """The kinds of ``task`` and the fits' ``rungs`` over them that can fit its states (``scene_rungs``)."""
    own = task_kinds(task)
    return own + [rung for rung in scene_rungs.fit_rungs(own, rungs) if _fits(task, rung)]


@functools.cache
def _fits(task: str, kind: str) -> bool:
    """Whether the kind's model (or a rung's, ``scene_rungs``) reads the scene's states: canonical [q, p] (its
    declared coordinates; the objectives would refuse its run otherwise), or, for a pixel model
    (``'latent'``), the frames its own encoder maps to its latent [q, p]; a fit must apply to the run too, and its
    model must build from what the task declares (the pair kind reads the bodies of 2body and 3body; spring has none);
    a rung its scene's page leaves out (``PAGES``' ``left_out``) is not studied there."""
    if kind in PAGES[page_of(task)]["left_out"]:
        return False
    if scene_rungs.kind_of(kind) not in hnn.cli.model_choices(hnn.load_task(task, "train").Config):
        return False        # the task's --model does not take it (the pixel task takes its own two)
    config = hnn.tasks.task_config(task, {"model": scene_rungs.kind_of(kind), "fit": scene_rungs.fit_of(kind)})
    spec = hnn.MODEL_KINDS[config.kind]
    if config.fit != "adam":
        try:
            hnn.fits.check_config(config, spec.coordinates)
        except ValueError:
            return False
    if not scene_rungs.builds(config):
        return False
    return spec.coordinates == "latent" or spec.reads("canonical")


def train(batches, out: Path, args, fits=None, then=None, who: str = "scene study",
          share: float | None = None) -> tuple[dict, dict]:
    """``({row/kind/seed: run folder or the error of a failed run}, seconds)`` of ``batches``, each
    ``(rows, seeds, steps, models or None for every kind)``: reuse what matches, train the rest
    in one sweep (``args.jobs`` processes, on ``args.backend``), so the pool starts once and the
    longest runs of every batch go first. ``fits(task, kind)``: which kinds fit the rows' states
    (default: the kinds of canonical states). ``then``: where given, the plan is printed first (its
    training measured, ``analysis/plan.py``), with ``then(models)`` the stages after it (``plan.Stage``s),
    ``models`` the count of runs the study will have; ``share``: the training's seconds of a quick budget."""
    fits = fits or _fits
    jobs = []
    for rows, seeds, steps, models in batches:
        models = kinds() if models is None else models
        # plan() always takes the paper's pair: keep only the kinds asked for; a fit's rung (``hnn+swim``) is
        # its own job (scene_rungs)
        jobs += [job for job in study.plan(rows, seeds, out / "runs", steps, models)
                 if job.config.model in models and fits(job.task, job.config.model)]
        jobs += scene_rungs.jobs(rows, seeds, out / "runs", models, fits)
    total = len(jobs)
    runs, jobs = sweep.reuse(jobs)
    sweep.say_reused(who, runs, jobs)
    if then is not None:
        jobs = plan.timed(jobs)
        plan.say(who, [plan.training(jobs, args.jobs if args.backend == "local" else 1, share), *then(total)])
    trained, seconds = sweep.train_jobs(jobs, args.jobs, out / "logs", args.backend, args.ray_address, args.group,
                                        args.device)
    runs.update(trained)
    return runs, seconds


def saved_numbers(row: dict, model, directory: Path) -> dict:
    """What a measured model's entry takes from its saved run: ``row`` is its ``study.load_runs`` row."""
    return {"test_loss": row["test_loss"], "train_loss": row["train_loss"], "train_seconds": row["train_seconds"],
            "params": sum(p.numel() for p in model.parameters()), "run": Path(directory).name,
            **({"equation": found} if (found := scene_rungs.equation(directory)) else {})}


class Scene:
    """A scene's truth: start states, the true trajectories over ``HORIZON`` training lengths, and
    the time over which the truth itself diverges from starts ``PERTURBATION`` apart."""

    def __init__(self, task: str, quick: bool, state: dict | None = None):
        self.task, self.system, self.cfg, self.quick = task, hnn.load_task(task), scene_settings(task), quick
        self.truth, self._at_step = None, {}
        if "T" in self.cfg:
            mode = QUICK if quick else FULL
            horizon = mode["horizon"] * self.cfg["T"]
            self.t = np.linspace(0.0, horizon, mode["points"] * mode["horizon"] + 1)
            self.x0 = settings.start_states(task, self.system, mode["starts"])
            if state is not None:       # another process integrated this truth already (``state()``)
                self.truth, self.divergence = torch.as_tensor(state["truth"]), state["divergence"]
                return
            with torch.no_grad():
                self.truth = hnn.evaluation.quiet_rollout(self.system.dynamics, self.x0, self.t, **sm.REFERENCE)
            self.divergence = sm.divergence_time(self.system.dynamics, self.x0, self.t, truth=self.truth)
        elif task == "real":
            # no truth past the measurements: the measured test segment, from its first state
            data = hnn.load_task("real").get_dataset()
            self.truth = torch.as_tensor(data["test_x"], dtype=torch.float64)[None]
            self.t = np.asarray(data["test_t"], dtype=np.float64) - float(data["test_t"][0])

    def rollout(self, model) -> dict | None:
        """The rollout error (``hnn.evaluation.rollout_errors``) of ``model`` on this scene's truth (None without
        one), on a float64 copy: a field by ``hnn.evaluation.ROLLOUT_SOLVER`` at the scene's times, a learned map by its own steps at
        its ``dt`` over the same horizon (``at_step``)."""
        if self.truth is None:
            return None
        model64 = hnn.evaluation.float64_copy(model)
        if not model.steps:
            return hnn.evaluation.rollout_errors(model64.time_derivative, self.truth, self.t, threads=None)
        t, truth = self.at_step(model.dt)
        return hnn.evaluation.rollout_errors(model64, truth, t, threads=None, options={})

    def at_step(self, dt: float) -> tuple[np.ndarray, torch.Tensor]:
        """``(times, truth)`` on multiples of ``dt`` over the scene's horizon: the truth integrated there
        (``sm.REFERENCE``, once per step), or the measured segment itself, whose times lie on its step."""
        if "T" not in self.cfg:
            return self.t, self.truth
        if dt not in self._at_step:
            t = dt * np.arange(int(np.floor(self.t[-1] / dt + 1e-9)) + 1)
            with torch.no_grad():
                self._at_step[dt] = t, hnn.evaluation.quiet_rollout(self.system.dynamics, self.x0, t, **sm.REFERENCE)
        return self._at_step[dt]

    @property
    def trials(self) -> int | None:
        """The trials of each energy protocol: ``study.QUICK_TRIALS`` in a quick study, else the protocol's."""
        return study.QUICK_TRIALS if self.quick else None

    def state(self) -> dict | None:
        """What another process needs to rebuild this scene without integrating its truth again."""
        if "T" not in self.cfg:
            return None
        return {"truth": self.truth.numpy(), "divergence": self.divergence}

    def measure(self, kind: str, directory: Path, protocols: bool = True) -> dict:
        """Losses, energy MSE (every protocol, if ``protocols``), rollout error and valid time of one
        run of model kind ``kind``."""
        trained, row = study.load_runs(self.task, {kind: directory})
        model = trained.models[kind]
        out = saved_numbers(row[kind], model, directory)
        tic = time.perf_counter()
        energy = registry.evaluate(trained, self.trials) if protocols else {}
        for name, result in energy.items():
            out[f"energy_mse_{name}"] = [result[kind]["mse"], result[kind]["mse_se"]]
        if self.truth is not None:
            out["rollout"] = self.rollout(model)
        elif self.task == "pixels" and "corrected" in energy:
            # the decoded frames of the corrected protocol's trajectory against the rendered ones
            result = energy["corrected"]
            truth = torch.as_tensor(result["truth"]["pixels"], dtype=torch.float64)[None]
            decoded = torch.as_tensor(result[kind]["decoded"], dtype=torch.float64)[None]
            frames = np.arange(truth.shape[1], dtype=np.float64)
            out["rollout"] = hnn.metrics.summarize_errors(hnn.metrics.relative_error(decoded, truth), frames)
            # the decoder's own reconstruction error of a frame is ~0.3 in this measure: no frame is
            # ever within 0.1, so a valid time in pixel space says nothing
            out["rollout"]["valid_time"] = None
        out["evaluate_seconds"] = time.perf_counter() - tic
        return out


def _energy_fn(system, model, kind: str):
    """The learned H of an H-model, else the system's own H (the drift a baseline shows)."""
    if hnn.MODEL_KINDS[scene_rungs.kind_of(kind)].conservative:
        return hnn.evaluation.float64_copy(model).hamiltonian
    return system.hamiltonian


def _periods(scene: Scene) -> float:
    """The period of the long drift run: the scene's, or for the orbits the median circular-orbit
    period 2 pi r / v of body 0 about the centre of mass."""
    if scene.cfg["period"] is not None:
        return scene.cfg["period"]
    x = scene.x0.numpy()
    n = x.shape[1] // 4     # bodies; x = [qx_i, qy_i, px_i, py_i] blocks of n
    r = np.hypot(x[:, 0], x[:, n])
    v = np.hypot(x[:, 2 * n], x[:, 3 * n])
    return float(np.median(2 * np.pi * r / v))


# the settings whose long-run drift is measured: the fastest of any solver, of a symplectic one, of one
# that keeps the field's H (the discrete gradient, for a field that carries its H)
PICKS = ("fastest", "fastest_symplectic", "fastest_energy_preserving")


def speed_study(scene: Scene, kind: str, model, quick: bool) -> dict:
    """Speed at equal accuracy of one model of kind ``kind``, and the drift of its energy over the long run."""
    model64 = hnn.evaluation.float64_copy(model)
    f = model64.field
    x0 = scene.x0[:4]
    t = np.linspace(0.0, scene.cfg["T"], 31)
    spec = hnn.MODEL_KINDS[scene_rungs.kind_of(kind)]
    ladder = sm.settings_ladder(scene.cfg["dts"], spec.separable, quick,
                                hnn.interface.carries_energy(f))
    mode = QUICK if quick else FULL
    result = sm.speed_at_accuracy(f, x0, t, ladder, mode["timings"])     # quick: a smoke run times once
    if scene.cfg.get("drift") and not spec.dissipative:
        period, periods = _periods(scene), (mode["drift_periods"] or scene.cfg["periods"])
        budget = mode["drift_budget"]
        energy = _energy_fn(scene.system, model, kind)
        for key in PICKS:
            pick = result[key]
            if pick is not None:
                pick["drift"] = sm.long_drift(f, energy, x0[:2], pick["options"], period, periods, budget)
        result["period"] = period
    return result
