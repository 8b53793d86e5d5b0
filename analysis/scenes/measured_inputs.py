"""The input of the study of your own file (``scene_study.py --data``), read and checked before torch loads:
its flags (``experiment-measured/train.py``'s column flags and the study's own) and ``check``, which reads
the file and its held-out tails, so that a missing file, a misspelled column or a horizon too long for the
tails is one ``error:`` line at once (``tests/test_score.py`` holds it torch-free).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import hnn
from hnn_analysis.scenes import measured_metrics as mm

TASK = "measured"
COLUMNS = ("data", "time", "q", "v", "p", "trial", "periodic", "dxdt", "test_fraction", "max_gap")


def add_flags(parser) -> None:
    """The column flags of experiment-measured/train.py, and the study's own."""
    defaults = hnn.tasks.load_task(TASK, "train").Config
    group = parser.add_argument_group("your own measurements (the study of one file instead of the shipped scenes)")
    for name in COLUMNS:
        meta = hnn.cli.field_meta(defaults, name)
        group.add_argument(f"--{name}", type=meta.get("parse") or str, default=getattr(defaults, name),
                           help=meta.get("help"))
    group.add_argument("--horizon", type=hnn.settings.positive_float, default=None,
                       help="seconds ahead of the prediction error (default: a tenth of the shortest held-out tail)")
    group.add_argument("--energy", default=None,
                       help="an energy of your columns as a numpy expression (e.g. '0.5*v**2 + 2*x**2'): its drift")


@dataclass
class Inputs:
    """A checked input: the task's data module, the columns (``data`` absolute), the recording, its held-out
    tails and the ``--energy`` function (or None)."""
    data: object
    columns: dict
    rec: object
    held: mm.Heldout
    energy: object


def check(args, parser) -> Inputs:
    """Read ``args.data`` as ``args`` name its columns and split it as the study will (notes printed once,
    here); a bad input is ``parser.error``: one line naming it and the fix."""
    data = hnn.tasks.load_task(TASK)
    columns = {name: getattr(args, name) for name in COLUMNS}
    columns["data"] = str(Path(args.data).expanduser().resolve()) if args.data else ""
    try:
        hnn.tasks.task_config(TASK, columns)
        rec = data.load(*(columns[k] for k in ("data", "time", "q", "v", "p", "trial", "periodic", "dxdt")))
        for note in rec.notes:
            print(f"note: {note}", flush=True)
        held = mm.Heldout(data, rec, args.test_fraction, args.horizon, args.max_gap)
        energy = mm.energy_function(args.energy, rec)
    except (ValueError, FileNotFoundError) as err:
        parser.error(str(err))
    return Inputs(data, columns, rec, held, energy)


def precheck(argv: list[str]) -> Inputs | None:
    """``check`` of a command line that has ``--data``, from its study flags alone (the others are the full
    parser's, after torch loads); None without ``--data``."""
    if not any(word == "--data" or word.startswith("--data=") for word in argv):
        return None
    parser = hnn.cli.Parser(prog="scene_study.py", add_help=False)
    add_flags(parser)
    args, _ = parser.parse_known_args(argv)
    return check(args, parser) if args.data else None
