"""One argument parser for every ``train.py``: the original's flags, declared and checked once.

Each task passes its own defaults (the original hard-coded some of them, such as the weight
decay; here every knob is a flag with the original's value as its default). A bad flag or
value stops the parse with the usage and one ``error: ...`` line naming the value and the fix
(exit code 2, as argparse). A flag declared ``display_only=True`` changes what is printed or how
fast, never what is trained: ``hnn.find_run`` ignores it when it looks for a saved run with the
same args (the parsed namespace lists them in ``args.display_only``). ``run_main`` runs a ``train.py`` as a command: the package's input
errors raised while running (a missing data file, say) become such a line too, and it prints
the run folder at the end.

    if __name__ == "__main__":
        hnn.cli.run_main(main)
"""
from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import torch

from .models import FIELD_TYPES, NONLINEARITIES
from .objectives import MODEL_KINDS

USAGE_ERROR = 2     # argparse's exit code for bad usage; input errors while running share it
# Exceptions that mean "the input is wrong", not "the code is": values the parser cannot check
# (the package raises ValueError naming the value and the fix), missing data files, and a
# --save_dir that cannot be written. Anything else keeps its traceback.
INPUT_ERRORS = (ValueError, FileNotFoundError, NotADirectoryError, PermissionError)
# the shared display-only flags (a task declares its own with display_only=True)
DISPLAY_ONLY = ("verbose", "debug")


def _one_line(text) -> str:
    """``text`` with every run of whitespace (newlines included) collapsed to one space."""
    return " ".join(str(text).split())


class RunArgs(argparse.Namespace):
    """Parsed flags; ``display_only`` (a slot, so not in ``vars(args)`` nor in args.json) names the
    flags that change what is printed or how fast, never what is trained."""
    __slots__ = ("display_only",)


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose error is the usage and then one line starting ``error: ``, and
    whose ``add_argument`` takes ``display_only=True`` (parsed into a ``RunArgs``)."""

    def __init__(self, *args, **kwargs):
        self.display_only: set[str] = set()
        super().__init__(*args, **kwargs)
        # argparse (before 3.13) reads "--learn_rate -1e-3" as a flag missing its value; no
        # option here looks like a number, so let every negative number reach the type check
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(USAGE_ERROR, f"error: {_one_line(message)}\n")

    def add_argument(self, *args, display_only: bool = False, **kwargs):
        action = super().add_argument(*args, **kwargs)
        if display_only:
            self.display_only.add(action.dest)
        return action

    def parse_known_args(self, args=None, namespace=None):
        if namespace is None:
            namespace = RunArgs()
            namespace.display_only = tuple(sorted(self.display_only))
        parsed, rest = super().parse_known_args(args, namespace)
        if hasattr(parsed, "model") and hasattr(parsed, "baseline"):
            _resolve_model(self, parsed)
        return parsed, rest


# ----------------------------------------------------------------------------------------------
# argparse types: each turns the flag's text into a value or raises a one-line error that says
# what is wanted (argparse prefixes "argument --flag: ")


def int_at_least(low: int, *, even: bool = False, why: str = "") -> Callable[[str], int]:
    """An argparse ``type``: an integer >= ``low`` (and even, if ``even``); ``why`` explains the rule."""
    rule = f"an {'even ' if even else ''}integer >= {low}{why}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low or (even and value % 2):
            raise argparse.ArgumentTypeError(f"must be {rule}, got {text!r}")
        return value

    return parse


def _finite_float(text: str, rule: str, ok: Callable[[float], bool]) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and ok(value)):
        raise argparse.ArgumentTypeError(f"must be a finite number {rule}, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """An argparse ``type``: a finite number > 0."""
    return _finite_float(text, "> 0", lambda v: v > 0)


def nonnegative_float(text: str) -> float:
    """An argparse ``type``: a finite number >= 0."""
    return _finite_float(text, ">= 0", lambda v: v >= 0)


def fraction(text: str) -> float:
    """An argparse ``type``: a finite number in (0, 1]."""
    return _finite_float(text, "in (0, 1]", lambda v: 0 < v <= 1)


def _optional_int(text: str) -> int | None:
    """``--batch_size``: a positive integer, or none/0/full for the full batch (None)."""
    if text.lower() in ("none", "0", "full"):
        return None
    return int_at_least(1, why=", or none/0/full for the full batch")(text)


def _fixed_width(width: int, task: str, state: str) -> Callable[[str], int]:
    """``--input_dim``: the original's flag, but the task fixes the state width; only it parses."""
    def parse(text: str) -> int:
        fix = f"drop the flag or pass --input_dim {width}"
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}; {fix}") from None
        if value != width:
            raise argparse.ArgumentTypeError(
                f"{value} does not match the {task} task's {state} of width {width}; {fix}")
        return value

    return parse


def _device(text: str) -> str:
    """``--device``: a torch device string this machine has (kept as text: it is saved in args.json)."""
    try:
        device = torch.device(text)
    except RuntimeError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a torch device; use e.g. cpu, cuda or cuda:1") from None
    backend = getattr(torch, device.type, None)     # torch.cuda, torch.mps, ...: None for exotic types
    if device.type != "cpu" and backend is not None and not backend.is_available():
        raise argparse.ArgumentTypeError(f"{text!r}: this torch build sees no {device.type} device; use --device cpu")
    if device.type != "cpu" and device.index is not None and backend is not None \
            and device.index >= backend.device_count():
        raise argparse.ArgumentTypeError(f"{text!r}: only {backend.device_count()} {device.type} device(s) here, "
                                         "numbered from 0")
    return text


# ----------------------------------------------------------------------------------------------
# the parser


def _model_choices() -> list[str]:
    """The model kinds a task's ``--model`` may name (the pixel kinds are the pixel task's own)."""
    return [kind for kind in MODEL_KINDS if "-" not in kind]


def _resolve_model(parser: argparse.ArgumentParser, args) -> None:
    """``--baseline`` means ``--model baseline`` (the original's flag); both set ``args.model`` and
    ``args.baseline`` consistently, and a contradiction is an error."""
    if args.baseline and args.model not in (None, "baseline"):
        parser.error(f"--baseline contradicts --model {args.model}; pass one of them")
    args.model = "baseline" if args.baseline else (args.model or "hnn")
    args.baseline = args.model == "baseline"


def make_parser(description: str, *, name: str, input_dim: int, save_dir: str, weight_decay: float,
                total_steps: int = 2000, batch_size: int | None = None, learn_rate: float = 1e-3,
                hidden_dim: int = 200, rk4_help: str | None = None,
                state: str = "state x = [q, p]") -> argparse.ArgumentParser:
    """The shared flags with one task's defaults; a task may add flags of its own.

    ``name`` is the task's name (the default run name); ``input_dim`` its fixed state width,
    the only value ``--input_dim`` accepts; ``state`` says what that width measures, for the
    error message.
    """
    p = Parser(description=description, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--input_dim", type=_fixed_width(input_dim, name, state), default=input_dim,
                   help=f"width of the {state} (fixed by the task)")
    p.add_argument("--hidden_dim", type=int_at_least(1), default=hidden_dim, help="hidden units per layer of the MLP")
    p.add_argument("--learn_rate", type=positive_float, default=learn_rate, help="Adam learning rate")
    p.add_argument("--weight_decay", type=nonnegative_float, default=weight_decay,
                   help="Adam weight decay (hard-coded per task in the original)")
    p.add_argument("--batch_size", type=_optional_int, default=batch_size,
                   help="minibatch size; none/0/full = full batch")
    p.add_argument("--train_fraction", type=fraction, default=1.0,
                   help="train on this fraction of the training rows, drawn once from the seed (the test set "
                        "stays whole); for studies of how much data a model needs")
    p.add_argument("--nonlinearity", type=str, default="tanh", choices=NONLINEARITIES,
                   help="activation of the MLP")
    p.add_argument("--total_steps", type=int_at_least(0), default=total_steps,
                   help="optimizer steps; the loop runs total_steps + 1, as the original")
    p.add_argument("--print_every", type=int_at_least(1), default=200, help="print (and test) every N steps")
    p.add_argument("--name", type=str, default=name, help="run name, the prefix of the run folder")
    p.add_argument("--baseline", action="store_true", help="train the baseline (an MLP predicting dx/dt directly); "
                   "the same as --model baseline")
    p.add_argument("--model", choices=_model_choices(), default=None,
                   help="model kind: hnn (the paper's), baseline, separable (H = T(p) + V(q): explicit leapfrog is "
                        "symplectic for it) or dissipative (J grad H + grad D: learns friction); default hnn")
    p.add_argument("--use_rk4", action="store_true", help=rk4_help or (
        "fit the RK4 average slope of the learned field over one data time step dt, (x(t+dt) - x(t))/dt "
        "of one RK4 step, to the true dx/dt (the original crashed on this flag); default: fit dx/dt itself"))
    p.add_argument("--verbose", action="store_true", display_only=True, help="print the loss every print_every steps")
    p.add_argument("--field_type", type=str, default="solenoidal", choices=FIELD_TYPES,
                   help="solenoidal (Hamiltonian), conservative, or both")
    p.add_argument("--seed", type=int_at_least(0), default=0,
                   help="seeds the dataset, the init and the minibatches")
    p.add_argument("--save_dir", type=str, default=save_dir,
                   help="folder that receives the run folder <name>-<hnn|baseline>-seed<seed>/")
    p.add_argument("--device", type=_device, default="cpu", help="torch device, e.g. cpu or cuda")
    p.add_argument("--dtype", type=str, default="float32", choices=("float32", "float64"),
                   help="dtype of the model and the data")
    p.add_argument("--debug", action="store_true", display_only=True,
                   help="on an input error (a missing data file, say), show the full traceback "
                        "instead of one error: line")
    return p


# ----------------------------------------------------------------------------------------------
# running a train.py as a command


def _wants_debug(argv: Sequence[str]) -> bool:
    """Whether ``argv`` holds ``--debug`` (or an abbreviation argparse would accept)."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--debug", action="store_true")
    return pre.parse_known_args(list(argv))[0].debug


def run_main(main: Callable[[list[str]], Path], argv: Sequence[str] | None = None) -> Path:
    """Run a ``train.py``'s ``main(argv)`` as a command (``argv`` defaults to ``sys.argv[1:]``).

    Prints ``saved the run to <folder>`` at the end and returns the folder. An input error
    raised while running (one of ``INPUT_ERRORS``) becomes one ``error: <message>`` line on
    stderr and exit code 2, or, with ``--debug``, propagates with its traceback.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        folder = main(argv)
    except INPUT_ERRORS as err:
        if _wants_debug(argv):
            raise
        print(f"error: {_one_line(err) or type(err).__name__}", file=sys.stderr)
        sys.exit(USAGE_ERROR)
    print(f"saved the run to {folder}")
    return folder
