"""Train a model of a Lennard-Jones cluster (N bodies in the plane, every pair; not one of the paper's tasks).

    python experiment-lj/train.py --model pairwise --verbose           # the pair kind, Adam
    python experiment-lj/train.py --model pairwise --fit library       # V(r) as an equation, one solve
    python experiment-lj/train.py --model pairwise --cutoff 2.5        # pairs closer than 2.5 only (a cell list)

The task declares its bodies (``BODIES``: 8 in 2-D, every pair), so the pair kind reads them and the
same model rolls out on a cluster of any size. ``--cutoff r_c`` makes the scene and the model short-range: the data's
true forces and the pair kind both read the truncated and shifted potential over the pairs closer than r_c, found at
each call by a cell list (``Bodies(pairs='cutoff')``).
"""
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import setting

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """Eight unit masses in the plane, every pair at the Lennard-Jones V(r) = 4 (r^-12 - r^-6)."""
    name: str = "lj"
    input_dim: int = 32
    save_dir: str = str(HERE)
    # minibatches of 200 states, as the 2-body task's and the bodies study's: a full batch of the 3200 training states
    # runs the pair kind's V over every pair of each (90000 distances a step on gravity: 1.2 steps/s on one thread)
    batch_size: int | None = 200
    # the bodies' columns differ in size by where each body sits (the cluster's rim), not by unit: the scene is in units
    # near 1 already, and scales per column would bend the pair kind's distances (hnn.units refuses them for it)
    units: str = setting("off", "train in the canonical units of the data (hnn.units): off (the default here: the scene "
                                "is in units near 1), auto or on (never for --model pairwise)", choices=hnn.names.UNITS,
                         identity_at_default=False)
    # 0, every pair, keeps the runs saved before the cutoff existed (their identity lacks it)
    cutoff: float = setting(0.0, "interact only the pairs closer than this (in units of sigma; > 0.7, the wall's range; "
                                 "2.5 is usual), in the data's true forces and the pair kind alike, found at each call "
                                 "by a cell list: the truncated and shifted V(r) - V(r_c); 0 (the default): every pair",
                            parse=hnn.settings.nonnegative_float, identity_at_default=False)
    BODIES: ClassVar[hnn.bodies.Bodies] = hnn.bodies.Bodies(count=8, dim=2)
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed", "save_dir", "cutoff")

    def layout(self) -> hnn.bodies.Bodies:
        """The layout this run reads: ``BODIES``, or its pairs closer than ``cutoff`` where one is set."""
        return dataclasses.replace(self.BODIES, pairs="cutoff", cutoff=self.cutoff) if self.cutoff else self.BODIES

    def model_facts(self) -> dict:
        """The task's bodies, which the pair kind reads."""
        return {"bodies": self.layout().to_dict()}

    def dataset(self) -> dict:
        return hnn.load_task("lj").get_dataset(seed=self.seed, save_dir=self.save_dir, cutoff=self.cutoff or None)


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
