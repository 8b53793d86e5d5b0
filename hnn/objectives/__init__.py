"""What a run fits: the dataset arrays a model trains on, its loss and its final numbers.

    hnn.run_experiment(config)                                   # config.make_objective(): the kind's
    hnn.run_experiment(config, dataset, hnn.objectives.PixelObjective(("pixels", "next_pixels", "test_pixels", "test_next_pixels")))

An objective gives ``hnn.train`` its options for a model and a dataset (``LoopOptions``, a frozen
record: objectives keep no state of a run), and measures the final train and test numbers with them.
Which objective trains which model kind is declared by the kinds' registry (``hnn.MODEL_KINDS``,
``hnn/kinds.py``); a new kind of objective is an ``Objective`` subclass, its name in
``hnn.names.OBJECTIVES`` and its row in ``hnn.kinds``' ``_OBJECTIVE_CLASSES``.

The family is this folder: the interface, the paper's derivative fit and the pixel task's here; the
trajectory objective (``trajectory``), DGNet's discrete-gradient pairs (``dgnet``) and a learned map's
step (``map``) beside it, each loaded on first use (``hnn.objectives.trajectory``).

A dataset says in which coordinates its states are (``dataset["state"]``, a key of
``hnn.interface.COORDINATES``; ``'canonical'`` if absent) and each model declares what it reads
(``hnn.Model``): the objectives fit the model's field in the dataset's coordinates
(``model.observed_field``), or refuse the pair with one error naming the fix.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, ClassVar

import torch
from torch import nn

from ..balance import balance_weights
from ..integrators.fixed_step import rk4_step
from ..interface import declared, observed_coordinates
from ..metrics import derivative_mse, mean_and_se
from ..settings import RunSettings
from ..specs import ObjectiveSpec
from ..training import batch_loss


@dataclass(frozen=True)
class LoopOptions:
    """What an objective gives the training loop for one model on one dataset (``Objective.train_options``),
    and what its final numbers read. The loop's part (``train_kwargs``, ``hnn.train``'s keywords of these
    names): ``loss`` ``(x, y) -> (batch,)`` or ``(batch, k)``, an objective's own (None: a fit of dx/dt
    built from ``predict``, ``derivative_loss`` and ``loss_weights``); ``predict`` ``x -> dx/dt`` (None:
    the model's ``time_derivative``); ``input_noise`` (std of the noise on each batch's inputs);
    ``generators`` (a loss's own random generators, checkpointed with the run). The final numbers'
    part: ``row_loss`` (the per-row loss of ``final_loss``; None: ``loss``) and ``field`` (the field a
    fit of dx/dt is scored by; None: the model's ``time_derivative``)."""
    loss: Callable | None = None
    predict: Callable | None = None
    derivative_loss: str = RunSettings.derivative_loss
    loss_weights: object = None
    input_noise: float = 0.0
    generators: tuple = ()
    row_loss: Callable | None = None
    field: Callable | None = None

    def train_kwargs(self) -> dict:
        """``hnn.train``'s keyword arguments of the loop's part."""
        return {"loss": self.loss, "predict": self.predict, "derivative_loss": self.derivative_loss,
                "loss_weights": self.loss_weights, "input_noise": self.input_noise, "generators": self.generators}

    def loss_of(self, model: nn.Module) -> Callable:
        """The batch loss ``(x, y) -> (batch, ...)`` the loop minimizes for ``model``
        (``hnn.training.batch_loss``: ``loss``, or the fit of dx/dt built from the other fields)."""
        return batch_loss(model, **self.train_kwargs())


class Objective:
    """The interface: subclasses implement ``train_options`` (a ``LoopOptions`` with a ``loss`` or a
    ``row_loss``, or override ``final_loss``); an objective holds its own settings, never a run's state.

    ``arrays`` names the dataset's ``(inputs, targets, test inputs, test targets)``, each ``(rows, width)``.
    """
    arrays: tuple[str, str, str, str] = ("x", "dxdt", "test_x", "test_dxdt")
    chunk = 4096        # rows per no-grad batch of final_loss
    # its first two arrays are states and their dx/dt, so that --units can rescale them (hnn.units)
    fits_derivative: ClassVar[bool] = False
    # whether its fit reads the data's rates (dx/dt, or states stepped through time by a field): a learned map's
    # fits a state to the next one and never reads a time, so --units auto judges its states' sizes alone
    reads_rates: ClassVar[bool] = True

    def prepare(self, dataset: dict) -> dict:
        """The dataset with the ``arrays`` this objective trains on (derived ones added); itself by default."""
        return dataset

    def train_options(self, model: nn.Module, spec: ObjectiveSpec, dataset: dict) -> LoopOptions:
        """What ``hnn.train`` adds to a run's ``TrainingSpec`` for ``model`` on ``dataset`` (``predict``,
        ``loss``, ...), from what the run's ``ObjectiveSpec`` asks (``hnn.specs.run_specs(config).objective``)."""
        return LoopOptions()

    def final_loss(self, model: nn.Module, inputs, targets, options: LoopOptions | None = None) -> tuple[float, float]:
        """The ``(mean, ±)`` train or test number saved in metrics.json: ``options.row_loss`` (else its
        ``loss``) over all rows, in no-grad batches of ``chunk`` rows, mean ± std/sqrt(rows). ``options``:
        ``train_options``' for ``model`` (default: on a dataset of canonical states, this objective's dt)."""
        options = options or self.train_options(model, ObjectiveSpec(), {})
        param = next(model.parameters())
        y = torch.as_tensor(targets, dtype=param.dtype, device=param.device)
        x = y if inputs is targets else torch.as_tensor(inputs, dtype=param.dtype, device=param.device)
        loss, c = options.row_loss or options.loss, self.chunk
        with torch.no_grad():
            per_row = [loss(x[i:i + c], y[i:i + c]) for i in range(0, len(y), c)]
        return mean_and_se(torch.cat([part if part.dim() == 1 else part.mean(1) for part in per_row]))


def cut_paths(dataset: dict, names: tuple[str, str], cut, needs: str) -> dict:
    """``dataset`` with the arrays ``names`` (train, test) cut by ``cut(rows, path_points)`` from its
    ``x`` and ``test_x`` paths (``t_eval`` gives the states per path), unless it has them already;
    ``needs`` starts the error for a dataset without paths (no ``dt`` and ``t_eval``)."""
    if all(name in dataset for name in names):
        return dataset
    if "dt" not in dataset or "t_eval" not in dataset:
        raise ValueError(f"{needs} needs paths: this task's dataset gives no {names[0]!r} and no 'dt' and 't_eval' "
                         "to cut its x into them; use --objective derivative")
    points = len(dataset["t_eval"])
    return {**dataset, names[0]: cut(dataset["x"], points), names[1]: cut(dataset["test_x"], points)}


class PathObjective(Objective):
    """An objective fit on consecutive observed states ``dt`` apart (the trajectory objective's
    snippets, DGNet's pairs): a subclass gives ``loss_for(model, dt, observed)``; ``train_options``
    reads the dataset's coordinates and time step (``dt`` and ``observed``, this object's: the defaults
    where a dataset says neither), and every row's loss is ``loss_for``'s."""
    dt: float | None = None
    observed: str = "canonical"

    def loss_for(self, model: nn.Module, dt: float | None = None, observed: str | None = None):
        raise NotImplementedError

    def train_options(self, model: nn.Module, spec: ObjectiveSpec, dataset: dict) -> LoopOptions:
        observed = observed_coordinates(dataset) if "state" in dataset else self.observed
        declared(model).relation(observed)      # a model that cannot read these states: one clear error
        dt = float(dataset["dt"]) if "dt" in dataset else self.dt
        return LoopOptions(loss=self.loss_for(model, dt, observed))


class DerivativeObjective(Objective):
    """The paper's objective: fit ``time_derivative(x)`` to ``dxdt`` (an HNN, or an MLP as the baseline).

    With ``use_rk4`` the prediction is the RK4 average slope over the dataset's ``dt``; with
    ``input_noise`` each training batch's inputs get Gaussian noise.
    """

    fits_derivative = True

    def train_options(self, model: nn.Module, spec: ObjectiveSpec, dataset: dict) -> LoopOptions:
        observed = observed_coordinates(dataset)
        targets = dataset.get(self.arrays[1])
        options = LoopOptions(input_noise=spec.input_noise, derivative_loss=spec.derivative_loss,
                             # --balance reads the training targets' sizes; a caller that passes none trains unweighted
                             loss_weights=None if spec.balance == "off" or targets is None
                             else balance_weights(targets, spec.balance, spec.derivative_loss))
        if declared(model).relation(observed) == "mapped":
            # a model of its own coordinates fit to d/dt of the observed states through its own map
            if spec.use_rk4:
                raise ValueError(f"--use_rk4 steps the model's own state; on observed {observed!r} states drop it")
            return replace(options, predict=model.observed_time_derivative, field=model.observed_time_derivative)
        if targets is not None and hasattr(model, "check_data_scale"):     # a model that knows what scale it can learn
            model.check_data_scale(dataset[self.arrays[0]], targets)
        if spec.use_rk4:
            if "dt" not in dataset:
                raise ValueError("--use_rk4 needs the dataset's time step; this task's get_dataset gives no 'dt'")
            dt = float(dataset["dt"])
            return replace(options, predict=lambda x: rk4_step(model.time_derivative, x, dt) / dt)
        return options

    def final_loss(self, model: nn.Module, inputs, targets, options: LoopOptions | None = None) -> tuple[float, float]:
        """The mean squared error of dx/dt (``options.field``'s where it maps states, else the model's own)."""
        return derivative_mse(model, inputs, targets, field=options.field if options else None)


def pixel_loss(model, x: torch.Tensor, x_next: torch.Tensor, input_noise: float = 0.0, use_rk4: bool = False,
               generator: torch.Generator | None = None) -> torch.Tensor:
    """The paper's per-sample loss ``(batch,)`` of a ``PixelHNN`` on pairs of observations one frame
    apart, ``x``, ``x_next`` ``(batch, input_dim)``: ae + cc + 0.1 hnn.

    ae = mean over pixels of (x - decode(z))^2; hnn = mean over latents of
    (z' - (z + step(z + noise)))^2, one frame step (Euler, or RK4 with ``use_rk4``); cc = mean over
    the n latent pairs of (p - (q' - q))^2, which makes p the per-frame change of q (z = [q, p],
    z' = encode(x_next)). ``input_noise``: std of the latent noise, drawn from ``generator``.
    """
    if x.shape != x_next.shape:
        raise ValueError(f"x and x_next must have the same shape, got {tuple(x.shape)} and {tuple(x_next.shape)}")
    z, z_next = model.encode(torch.cat([x, x_next])).split(len(x))
    # mse_loss has a fused backward, cheaper than pow(2)'s (docs/speed.md, "Why the fast paths")
    ae = nn.functional.mse_loss(model.decode(z), x, reduction="none").mean(dim=1)
    zin = z if not input_noise else z + input_noise * torch.randn(z.shape, generator=generator, device="cpu").to(z)
    step = rk4_step(model.time_derivative, zin, 1.0) if use_rk4 else model.time_derivative(zin)
    hnn = (z_next - (z + step)).pow(2).mean(dim=1)
    n = model.latent_dim // 2
    cc = (z[:, n:] - (z_next[:, :n] - z[:, :n])).pow(2).mean(dim=1)
    return ae + cc + 0.1 * hnn


class PixelObjective(Objective):
    """``pixel_loss``: an autoencoder whose latent moves by an HNN (or an MLP), fit on pairs of
    observations one frame apart. ``arrays`` names the dataset's (observations, the next ones,
    and their test twins), each ``(rows, input_dim)``.

    The latent noise (``input_noise``) draws from its own generator seeded ``seed + 2``;
    ``use_rk4`` steps the latent by RK4 instead of Euler.
    """
    chunk = 4000

    def __init__(self, arrays: tuple[str, str, str, str] = ("x", "x_next", "test_x", "test_x_next")):
        self.arrays = tuple(arrays)

    def train_options(self, model: nn.Module, spec: ObjectiveSpec, dataset: dict) -> LoopOptions:
        noise = torch.Generator().manual_seed(spec.seed + 2)

        def loss(x, x_next):
            return pixel_loss(model, x, x_next, input_noise=spec.input_noise, use_rk4=spec.use_rk4, generator=noise)
        # a resumed run draws on where it stopped; the final numbers: the loss without noise
        return LoopOptions(loss=loss, generators=(noise,), row_loss=lambda x, x_next: pixel_loss(model, x, x_next))


_MODULES = ("dgnet", "map", "trajectory")


def __getattr__(name: str):
    """The family's other modules, loaded on first use (each imports this one)."""
    if name in _MODULES:
        import importlib
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
