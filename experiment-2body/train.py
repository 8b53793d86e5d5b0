"""Train the baseline or the HNN on task 4, two bodies under gravity (the original's flags and defaults).

    python experiment-2body/train.py --verbose              # HNN
    python experiment-2body/train.py --verbose --baseline   # baseline

The dataset (1000 orbits, 50000 rows) is generated once per seed and cached as an .npz in
--save_dir. Weight decay 0 is the original's hard-coded value.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import task_setting

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.orbits.config.OrbitConfig):
    """Task 4: two bodies under Newtonian gravity (G = 1, unit masses)."""
    name: str = "2body"
    input_dim: int = 8
    weight_decay: float = 0.0
    total_steps: int = 10000
    batch_size: int | None = 200
    save_dir: str = str(HERE)
    input_noise: float = task_setting("input_noise", help="std of Gaussian noise added to each training batch's "
                                                          "inputs x (the original declared it type=int, so only whole "
                                                          "numbers parsed, and added the noise to the predicted "
                                                          "derivatives instead)")
    TASK: ClassVar[str] = "2body"
    BODIES: ClassVar[hnn.bodies.Bodies] = hnn.bodies.Bodies(count=2, dim=2)      # the original's order


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
