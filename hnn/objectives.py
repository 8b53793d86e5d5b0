"""What a run fits: the model kind, the dataset arrays it trains on, its loss and its final numbers.

    hnn.run_experiment(args, dataset)                          # DerivativeObjective: x -> dx/dt
    hnn.run_experiment(args, dataset, hnn.PixelObjective(("pixels", "next_pixels", "test_pixels", "test_next_pixels")))

An objective builds the untrained model that a run's args describe (its init draws from torch's
global generator, seeded by the run), gives ``hnn.train`` its options, and measures the final
train and test numbers. Its model kind (``'hnn'``, ``'baseline'``, ``'pixel-hnn'``,
``'pixel-baseline'``) is saved in the run's ``args.json`` as ``"model"``, and ``model_from_args``
rebuilds a saved run's model from it through ``MODEL_KINDS``. A new model kind is one entry there
(``register_model_kind(name, objective class, build)``); a new kind of objective is an
``Objective`` subclass.
"""
from __future__ import annotations

import torch
from torch import nn

from .integrate import rk4_step
from .metrics import derivative_loss, mean_and_se
from .models import PixelHNN, build_model
from .structured import DissipativeHNN, SeparableHNN

DTYPES = {"float32": torch.float32, "float64": torch.float64}


class Objective:
    """The interface: subclasses set ``prefix`` and implement ``build`` and ``final_loss``.

    ``arrays`` names the dataset's ``(inputs, targets, test inputs, test targets)``, each ``(rows, width)``.
    """
    prefix = ""
    arrays: tuple[str, str, str, str] = ("x", "dxdt", "test_x", "test_dxdt")

    def kind(self, args: dict) -> str:
        """The model kind of a run with these args, saved as ``"model"`` in its args.json: the
        ``model`` flag when a task has one, else this objective's baseline or HNN."""
        label = args.get("model") or ("baseline" if args["baseline"] else "hnn")
        return label if label.startswith(self.prefix) else self.prefix + label

    def build(self, args: dict) -> nn.Module:
        """The untrained model of this run's kind (float32 unless ``args["dtype"]`` says otherwise)."""
        return _typed(_registered(self.kind(args))[1](args), args)

    def train_options(self, model: nn.Module, args: dict, dataset: dict) -> dict:
        """Keyword arguments for ``hnn.train`` beyond the shared flags (``predict``, ``loss``, ...)."""
        return {}

    def final_loss(self, model: nn.Module, inputs, targets) -> tuple[float, float]:
        """The ``(mean, ±)`` train or test number saved in metrics.json."""
        raise NotImplementedError


def _typed(model: nn.Module, args: dict) -> nn.Module:
    return model.to(dtype=DTYPES[args.get("dtype", "float32")])


class DerivativeObjective(Objective):
    """The paper's objective: fit ``time_derivative(x)`` to ``dxdt`` (an HNN, or an MLP as the baseline).

    With ``use_rk4`` the prediction is the RK4 average slope over the dataset's ``dt``; with
    ``input_noise`` each training batch's inputs get Gaussian noise.
    """

    def train_options(self, model: nn.Module, args: dict, dataset: dict) -> dict:
        options = {"input_noise": args.get("input_noise", 0.0), "predict": None}
        if args.get("use_rk4"):
            if "dt" not in dataset:
                raise ValueError("--use_rk4 needs the dataset's time step; this task's get_dataset gives no 'dt'")
            dt = float(dataset["dt"])
            options["predict"] = lambda x: rk4_step(model.time_derivative, x, dt) / dt
        return options

    def final_loss(self, model: nn.Module, inputs, targets) -> tuple[float, float]:
        return derivative_loss(model, inputs, targets)


class PixelObjective(Objective):
    """``PixelHNN.loss``: an autoencoder whose latent moves by an HNN (or an MLP), fit on pairs of
    observations one frame apart. ``arrays`` names the dataset's (observations, the next ones,
    and their test twins), each ``(rows, input_dim)``.

    The latent noise (``input_noise``) draws from its own generator seeded ``seed + 2``;
    ``use_rk4`` steps the latent by RK4 instead of Euler.
    """
    prefix = "pixel-"

    def __init__(self, arrays: tuple[str, str, str, str] = ("x", "x_next", "test_x", "test_x_next")):
        self.arrays = tuple(arrays)

    def train_options(self, model: nn.Module, args: dict, dataset: dict) -> dict:
        noise = torch.Generator().manual_seed(args["seed"] + 2)

        def loss(x, x_next):
            return model.loss(x, x_next, input_noise=args["input_noise"], use_rk4=args["use_rk4"], generator=noise)
        return {"loss": loss}

    def final_loss(self, model: nn.Module, inputs, targets, chunk: int = 4000) -> tuple[float, float]:
        """The per-sample loss over all rows (in chunks of ``chunk``), mean ± std/sqrt(rows)."""
        param = next(model.parameters())
        x = torch.as_tensor(inputs, dtype=param.dtype, device=param.device)
        x_next = torch.as_tensor(targets, dtype=param.dtype, device=param.device)
        with torch.no_grad():
            per_sample = torch.cat([model.loss(x[i:i + chunk], x_next[i:i + chunk]) for i in range(0, len(x), chunk)])
        return mean_and_se(per_sample)


def _mlp_model(baseline: bool):
    def build(args: dict) -> nn.Module:
        return build_model(args["input_dim"], args["hidden_dim"], args["nonlinearity"], baseline, args["field_type"])
    return build


def _pixel_model(baseline: bool):
    def build(args: dict) -> nn.Module:
        return PixelHNN(args["input_dim"], args["latent_dim"], args["hidden_dim"], args["nonlinearity"], baseline,
                        args["field_type"], args.get("ae_nonlinearity", "relu"))
    return build


def _structured_model(cls):
    def build(args: dict) -> nn.Module:
        return cls(args["input_dim"], args["hidden_dim"], args["nonlinearity"])
    return build


# model kind -> (the objective that trains it, its builder from a run's args): the one place a kind is named
MODEL_KINDS = {
    "hnn": (DerivativeObjective, _mlp_model(False)),
    "baseline": (DerivativeObjective, _mlp_model(True)),
    "separable": (DerivativeObjective, _structured_model(SeparableHNN)),
    "dissipative": (DerivativeObjective, _structured_model(DissipativeHNN)),
    "pixel-hnn": (PixelObjective, _pixel_model(False)),
    "pixel-baseline": (PixelObjective, _pixel_model(True)),
}


def register_model_kind(name: str, objective: type, build) -> None:
    """Add a model kind: runs whose args say ``"model": name`` train with ``objective`` and
    ``build(args) -> nn.Module`` makes their untrained model (and rebuilds it on load)."""
    if name in MODEL_KINDS:
        raise ValueError(f"model kind {name!r} is registered already")
    MODEL_KINDS[name] = (objective, build)


def _registered(kind: str) -> tuple:
    if kind not in MODEL_KINDS:
        raise ValueError(f"unknown model kind {kind!r}; known: {sorted(MODEL_KINDS)}")
    return MODEL_KINDS[kind]


def _kind(args: dict) -> str:
    """The saved ``"model"``; for runs saved before it was recorded, read off the args they hold."""
    if args.get("model"):
        return args["model"]
    return ("pixel-" if "latent_dim" in args else "") + ("baseline" if args["baseline"] else "hnn")


def objective_for(kind: str) -> Objective:
    """An objective that trains models of ``kind`` (its arrays are the defaults)."""
    return _registered(kind)[0]()


def model_from_args(args: dict) -> nn.Module:
    """The untrained model that a run with these (saved) args trains, of the kind it recorded."""
    return objective_for(_kind(args)).build({**args, "model": _kind(args)})
