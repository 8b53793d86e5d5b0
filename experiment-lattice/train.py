"""Train a model of a chain of springs (N bodies in the plane, neighbours joined; not one of the paper's tasks).

    python experiment-lattice/train.py --model pairwise --verbose           # the pair kind, Adam
    python experiment-lattice/train.py --model pairwise --fit library       # V(r) as an equation, one solve

The task declares its bodies (``BODIES``: 8 in 2-D, neighbours along the chain), so the pair kind reads them
and the same model rolls out on a chain of any length (``analysis/bodies.py``).
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import setting

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """A chain of 8 unit masses joined by springs (k = 1, rest length 1), moving in the plane."""
    name: str = "lattice"
    input_dim: int = 32
    save_dir: str = str(HERE)
    # minibatches of 200 states, as the 2-body task's and the bodies study's: a full batch of the 3200 training states
    # runs the pair kind's V over every pair of each (90000 distances a step on gravity: 1.2 steps/s on one thread)
    batch_size: int | None = 200
    # the bodies' columns differ in size by where each body sits (the chain's ends), not by unit: the scene is in units
    # near 1 already, and scales per column would bend the pair kind's distances (hnn.units refuses them for it)
    units: str = setting("off", "train in the canonical units of the data (hnn.units): off (the default here: the scene "
                                "is in units near 1), auto or on (never for --model pairwise)", choices=hnn.names.UNITS,
                         identity_at_default=False)
    BODIES: ClassVar[hnn.bodies.Bodies] = hnn.bodies.Bodies(count=8, dim=2, pairs="neighbours")
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed", "save_dir")

    def model_facts(self) -> dict:
        """The task's bodies, which the pair kind reads."""
        return {"bodies": self.BODIES.to_dict()}

    def dataset(self) -> dict:
        return hnn.load_task("lattice").get_dataset(seed=self.seed, save_dir=self.save_dir)


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
