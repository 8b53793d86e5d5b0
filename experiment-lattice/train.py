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

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """A chain of 8 unit masses joined by springs (k = 1, rest length 1), moving in the plane."""
    name: str = "lattice"
    input_dim: int = 32
    save_dir: str = str(HERE)
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
