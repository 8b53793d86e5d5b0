"""Train a model of N bodies under gravity, softened (not one of the paper's tasks).

    python experiment-gravity/train.py --model pairwise --verbose                        # the pair kind, Adam
    python experiment-gravity/train.py --model pairwise --fit library --softening 0     # Newton's -1/r, one solve

The task declares its bodies (``BODIES``: 8 in 2-D, every pair), so the pair kind reads them and the same
model rolls out any number of bodies.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import setting, task_setting

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """Eight unit masses in the plane under gravity (G = 1), Plummer-softened."""
    name: str = "gravity"
    input_dim: int = 32
    save_dir: str = str(HERE)
    # minibatches of 200 states, as the 2-body task's and the bodies study's: a full batch of the 3200 training states
    # runs the pair kind's V over every pair of each (90000 distances a step on gravity: 1.2 steps/s on one thread)
    batch_size: int | None = 200
    # the shared task setting (stage model): the data's V and the radial library's softened term read this one e
    softening: float = task_setting("softening", default=0.1, help="Plummer softening length e of V = -1 / "
                                    "sqrt(r^2 + e^2); 0 is Newton's (close encounters are then redrawn)")
    # the bodies' columns differ in size by where each body sits in the disk, not by unit: the scene is in units
    # near 1 already, and scales per column would bend the pair kind's distances (hnn.units refuses them for it)
    units: str = setting("off", "train in the canonical units of the data (hnn.units): off (the default here: the scene "
                                "is in units near 1), auto or on (never for --model pairwise)", choices=hnn.names.UNITS,
                         identity_at_default=False)
    BODIES: ClassVar[hnn.bodies.Bodies] = hnn.bodies.Bodies(count=8, dim=2)
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed", "save_dir", "softening")

    def model_facts(self) -> dict:
        """The task's bodies, which the pair kind reads."""
        return {"bodies": self.BODIES.to_dict()}

    def dataset(self) -> dict:
        return hnn.load_task("gravity").get_dataset(seed=self.seed, save_dir=self.save_dir, softening=self.softening)


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
