"""Train any model kind on your own measurements (a CSV, text or .npz file).

    python experiment-measured/train.py --data experiment-measured/systems/real_linear_h_1.txt \\
        --time t --q x --v v --trial trial --model hnn --verbose

The column flags name what the file holds (data.py reads it, differences it on its own time steps,
splits it by time within each trial and scales it so Hamilton's equations keep their form); the
run folder gets ``scale.json`` beside its config, metrics and checkpoint, so its numbers can be
turned back into your units. docs/measured.md walks through it.

On [q, v] (``--v``) the hnn, separable and dissipative kinds read v as the momentum (p = m v with
one constant mass, see data.ASSUMES; printed when you train one); mechanical learns the mass
matrix M(q) and second_order needs velocities (it is refused on [q, p]).
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import setting, task_setting
from hnn.io import write_json

HERE = Path(__file__).resolve().parent
PERIODIC_KINDS = ("mechanical", "second_order")     # kinds whose networks see (cos q, sin q) for all q or none


def _width(text: str) -> int:
    return hnn.settings.int_at_least(2, even=True, why=" (2 per --q column; --q sets it)")(text)


def _test_fraction(text: str) -> float:
    value = hnn.settings.fraction(text)
    if value >= 1:
        raise hnn.cli.argparse.ArgumentTypeError(f"must be below 1 (some rows must train), got {text!r}")
    return value


@dataclass
class Config(hnn.RunConfig):
    """Your own measurements: trajectories of any system from a file, x = [q, v] or [q, p]."""
    name: str = "measured"
    input_dim: int = setting(2, "width of the state: 2 per --q column (set by --q)", parse=_width)
    data: str = setting("", "the measurements: a .csv, whitespace-separated text with a header line (a leading %% or # "
                            "allowed), or an .npz of 1-D columns", parse=str)
    time: str = setting("t", "the column of times (seconds, or your unit of time)", parse=str)
    q: str = setting("", "the position columns, comma-separated (e.g. x1,x2)", parse=str)
    v: str = setting("", "their velocities, one per --q column (state [q, v]); or give --p", parse=str)
    p: str = setting("", "their canonical momenta, one per --q column (state [q, p]); or give --v", parse=str)
    trial: str = setting("", "the column that numbers the recordings, if the file holds several (rows of one trial "
                             "contiguous)", parse=str)
    periodic: str = task_setting("periodic", default="", parse=str,
                                 help="the --q columns that are angles in radians (unwrapped or wrapped); mechanical "
                                      "and second_order see (cos q, sin q)")
    dxdt: str = setting("", "columns of measured dx/dt (d/dt of every --q, then every --v/--p column) instead of "
                            "finite differences", parse=str)
    test_fraction: float = setting(0.3, "the last fraction of each trial's rows is held out", parse=_test_fraction)
    max_gap: float = setting(3.0, "no finite difference spans a time step over this many nominal (median) steps",
                             parse=hnn.settings.positive_float)
    save_dir: str = str(HERE)
    STATE: ClassVar[str] = "state [q, v] or [q, p]"
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("data", "time", "q", "v", "p", "trial", "periodic", "dxdt",
                                                 "test_fraction", "max_gap", "objective", "snippet_steps")

    def __post_init__(self):
        q = hnn.tasks.load_task("measured", "reader").names(self.q)
        if q:
            self.input_dim = 2 * len(q)
        angles = hnn.tasks.load_task("measured", "reader").names(self.periodic)
        if self.model in PERIODIC_KINDS and angles and set(angles) != set(q):
            raise ValueError(f"--model {self.model} sees (cos q, sin q) for every position or for none, and --periodic "
                             f"names {', '.join(angles)} of {', '.join(q)}; mark all or none, or use another --model")

    def dataset(self) -> dict:
        return hnn.tasks.load_task("measured").get_dataset(
            self.data, self.time, self.q, self.v, self.p, self.trial, self.periodic, self.dxdt, self.test_fraction,
            self.max_gap, self.snippet_steps if self.objective == "trajectory" else None)

    def finish(self, directory, dataset: dict) -> None:
        """The scale beside the run: its numbers in your units are q = q' a + q0, s = s' b, t = t' tau."""
        write_json(Path(directory) / "scale.json", {**dataset["scale"], "state": dataset["state"],
                                                    "periodic": dataset["periodic"], "data": dataset["cache_key"]})


def _notes(config: Config) -> None:
    """The notes on this input, before training: how the file was read, a position that looks like an
    unwrapped angle, and what the kind assumes of velocities."""
    data = hnn.tasks.load_task("measured")
    if config.data:
        for note in data.load(config.data, config.time, config.q, config.v, config.p, config.trial, config.periodic,
                              config.dxdt).notes:
            print(f"note: {note}")
    if config.v and config.model in ("hnn", "separable", "dissipative"):
        print(f"note: {data.ASSUMES}")


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run
    folder (checkpoint, args.json, metrics.json, scale.json)."""
    return hnn.command.train(Config, argv, before=_notes)


if __name__ == "__main__":
    hnn.command.run_main(main)
