"""The command line of every ``train.py``, built from its ``hnn.RunConfig`` subclass.

Every field of the config is a flag with the field's name and default (``--input_dim``,
``--total_steps``, ``--verbose``, ...); ``--baseline``, the original's flag, means ``--model
baseline``. A bad flag or value stops the parse with one ``error: ...`` line naming the value and
the fix (exit code 2, as argparse; the usage is ``--help``'s); a misspelled flag gets the nearest
real one ("did you mean --total_steps?"), and no flag is taken for an abbreviation of another. So
does a ``--save_dir`` that is a file or cannot be written, before anything trains.

A ``train.py``'s whole command (parse, reuse or train, say where) is ``hnn.command``'s. Nothing here
imports torch: ``--help`` and flag errors answer before it loads.

    config = hnn.cli.parse(Config, argv)
"""
from __future__ import annotations

import argparse
import dataclasses
import difflib
import inspect
import re
from collections.abc import Callable, Sequence
from pathlib import Path

from . import kind_docs
from .kinds import MODEL_KINDS, described
from .io import check_save_dir

USAGE_ERROR = 2     # argparse's exit code for bad usage; input errors while running share it (hnn.command)


def one_line(text) -> str:
    """``text`` with every run of whitespace (newlines included) collapsed to one space."""
    return " ".join(str(text).split())


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose error is one line starting ``error: `` (no usage block above it: the
    line names the flag and the fix, and ``--help`` shows the usage). Every command's parser is one."""

    def __init__(self, *args, **kwargs):
        # "--total_step 30" must not silently mean --total_steps: no abbreviations
        super().__init__(*args, allow_abbrev=False, **kwargs)
        # argparse (before 3.13) reads "--learn_rate -1e-3" as a flag missing its value; no
        # option here looks like a number, so let every negative number reach the type check
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")

    def error(self, message):
        self.exit(USAGE_ERROR, f"error: {one_line(message)}{self._suggestion(message)}\n")

    def _suggestion(self, message: str) -> str:
        """"; did you mean --x?" for each unknown flag of an "unrecognized arguments" ``message``
        that is close to a real one, or "; did you mean 'x'?" for an "invalid choice" close to one of
        the flag's choices; empty otherwise."""
        choice = re.match(r"argument (--\w+): invalid choice: '([^']*)'", message)
        if choice:
            action = self._option_string_actions.get(choice.group(1))
            return _did_you_mean(choice.group(2), [str(c) for c in getattr(action, "choices", None) or ()])
        if not message.startswith("unrecognized arguments:"):
            return ""
        known = [flag for flag in self._option_string_actions if flag.startswith("--")]
        hints = []
        for word in message.split(":", 1)[1].split():
            flag = word.split("=", 1)[0]
            close = nearest_flag(flag, known) if flag.startswith("--") else None
            if close:
                hints.append(f"{flag}: did you mean {close}?")
        return "; " + "; ".join(hints) if hints else ""


def nearest_flag(flag: str, known: Sequence[str]) -> str | None:
    """The real flag of ``known`` a mistyped ``flag`` most likely means, or None. Its words (split at '-' and
    '_', which the flags spell '_') decide first: the same words (``--total-steps``), a real flag that is
    its first words (``--fit-type``: ``--fit``, not the letters' nearest ``--field_type``), or a flag it
    starts (``--total``: ``--total_steps``, where only one does); then the nearest spelling (difflib)."""
    words = [w for w in re.split(r"[-_]+", flag.lstrip("-").lower()) if w]
    by_words = {flag_: [w for w in re.split(r"[-_]+", flag_.lstrip("-").lower()) if w] for flag_ in known}
    same = [f for f, w in by_words.items() if w == words]
    heads = sorted((f for f, w in by_words.items() if w and w == words[:len(w)]), key=lambda f: -len(by_words[f]))
    starts = [f for f, w in by_words.items() if "_".join(w).startswith("_".join(words))]
    if same or heads or len(starts) == 1:
        return (same or heads or starts)[0]
    close = difflib.get_close_matches("--" + "_".join(words), list(known), n=1, cutoff=0.6)
    return close[0] if close else None


def _did_you_mean(value: str, choices: Sequence[str]) -> str:
    """"; did you mean 'x'?" for the choice nearest ``value`` ("seperable" -> separable), or empty."""
    close = difflib.get_close_matches(value, list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


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


# ----------------------------------------------------------------------------------------------
# the parser of a config class


def field_meta(cls: type, name: str) -> dict:
    """The ``hnn.settings.setting`` metadata of field ``name`` of dataclass ``cls``: a subclass that
    only changes a default inherits the help text and parsing of the class that declared the field."""
    for klass in cls.__mro__:
        found = getattr(klass, "__dataclass_fields__", {}).get(name)
        if found is not None and found.metadata:
            return dict(found.metadata)
    return {}


def registered_kinds() -> list[str]:
    """Every model kind ``hnn.MODEL_KINDS`` holds (a torch-free table: known before torch loads), in its
    order, a kind registered at run time among them."""
    return list(MODEL_KINDS)


def model_choices(cls=None) -> list[str]:
    """The model kinds ``--model`` of config class ``cls`` takes: its ``MODELS``, else every
    registered kind of no family (``ModelKind.family``: the pixel kinds are the pixel task's own)."""
    declared = getattr(cls, "MODELS", None)
    return list(declared) if declared else [kind for kind in registered_kinds() if MODEL_KINDS[kind].family is None]


def _flag_type(cls, f: dataclasses.Field, meta: dict):
    """How the text of field ``f``'s flag becomes its value."""
    if f.name == "input_dim" and not meta.get("parse"):
        # the original's flag, but the task fixes the state width: only that value parses
        return _fixed_width(f.default, getattr(cls, "name", "this"), getattr(cls, "STATE", "state"))
    if meta.get("parse"):
        return meta["parse"]
    return type(f.default) if f.default is not None else str


def make_parser(cls, description: str | None = None) -> Parser:
    """An argparse parser with one flag per field of the config dataclass ``cls``, its
    ``setting`` help and parsing, the class's defaults, and ``--baseline`` beside ``--model``."""
    help_of = getattr(cls, "HELP", {})
    p = Parser(description=description or inspect.getdoc(cls), formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    for f in dataclasses.fields(cls):
        meta = field_meta(cls, f.name)
        text = help_of.get(f.name, meta.get("help", ""))
        if f.type in (bool, "bool") and f.default:
            # a switch that is on by default: --name / --no-name
            p.add_argument(f"--{f.name}", action=argparse.BooleanOptionalAction, default=True, help=text)
        elif f.type in (bool, "bool"):
            p.add_argument(f"--{f.name}", action="store_true", help=text)
        elif f.name == "model":
            # no argparse default, so that --baseline can tell an explicit --model from none
            kinds = model_choices(cls)
            prefix = getattr(cls, "KIND_PREFIX", "")
            kind_help = kind_docs.model_help(kinds, dict(described()), prefix)
            p.add_argument("--model", choices=kinds, default=argparse.SUPPRESS, help=f"{kind_help} (default: {f.default})")
            p.add_argument("--baseline", action="store_true",
                           help="train the baseline (an MLP predicting dx/dt directly): the original's flag, the "
                                "same as --model baseline")
        else:
            p.add_argument(f"--{f.name}", type=_flag_type(cls, f, meta), choices=meta.get("choices"),
                           default=f.default, help=text)
    return p


def parse(cls, argv: Sequence[str] | None = None):
    """The config of class ``cls`` that the command line ``argv`` (default ``sys.argv[1:]``) asks
    for; a bad flag or value exits with one ``error:`` line (code 2). Creates ``--save_dir``."""
    return parse_created(cls, argv)[0]


def parse_created(cls, argv: Sequence[str] | None) -> tuple:
    """``(config, the folders this parse created for save_dir, deepest first: none if it existed)``."""
    parser = make_parser(cls)
    values = vars(parser.parse_args(argv))
    # the original's --baseline is --model baseline: this is the one place it is mapped
    model = values.get("model", cls.model)
    if values.pop("baseline", False):
        if values.get("model", "baseline") != "baseline":
            parser.error(f"--baseline contradicts --model {model}; pass one of them")
        model = "baseline"
    values["model"] = model
    target = Path(values["save_dir"])
    created = [folder for folder in (target, *target.parents) if not folder.exists()]
    try:
        check_save_dir(values["save_dir"])
    except ValueError as err:
        parser.error(f"--{err}")
    return cls(**values), created


def check(config) -> None:
    """Raise ValueError naming the field, the value and the rule, for a config built in Python
    with a value its flag would refuse."""
    cls = type(config)
    for f in dataclasses.fields(cls):
        value, meta = getattr(config, f.name), field_meta(cls, f.name)
        choices = model_choices(cls) if f.name == "model" else meta.get("choices")
        if choices and value not in choices:
            raise ValueError(f"{f.name}={value!r}: choose one of {', '.join(map(str, choices))}"
                             + _did_you_mean(str(value), [str(c) for c in choices]))
        if isinstance(value, bool) or (value is None and f.default is None):     # a switch, or an unset option
            continue
        if meta.get("parse") or f.name == "input_dim":
            try:
                _flag_type(cls, f, meta)(str(value))
            except argparse.ArgumentTypeError as err:
                raise ValueError(f"{f.name}={value!r}: {err}") from None
