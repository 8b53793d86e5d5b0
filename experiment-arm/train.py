"""Train a model of the two-link arm from derivatives of random states (not one of the paper's tasks).

    python experiment-arm/train.py --model mechanical --verbose     # learned M(q) and V(q)
    python experiment-arm/train.py --model hnn --verbose            # the paper's HNN on [q, p]

States are canonical [q_1, q_2, p_1, p_2] (joint angles in radians, momenta in kg m^2 / s), fit on
dx/dt at every state (the paper's objective). ``python analysis/arm.py`` trains the kinds at one
budget and measures the field and rollout errors (docs/scenes.md, "The two-link arm").
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import setting, task_setting

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """The two-link arm in a vertical plane: H = 1/2 p^T M(q)^-1 p + V(q), M varying 4x with the elbow."""
    name: str = "arm"
    input_dim: int = 4
    n_train: int = setting(2000, "training states (random q and qdot)", parse=hnn.settings.int_at_least(1))
    n_test: int = setting(1000, "test states, drawn under seed + 1", parse=hnn.settings.int_at_least(1))
    mass: float = setting(1.0, "mass of each link in kg (M, V and p scale with it; the motions do not)",
                          parse=hnn.settings.positive_float)
    periodic: bool = task_setting("periodic", default=True)
    save_dir: str = str(HERE)
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed", "n_train", "n_test", "mass")

    def __post_init__(self):
        if self.input_dim != 4:
            raise ValueError(f"input_dim={self.input_dim}: the arm's state [q_1, q_2, p_1, p_2] has width 4; "
                             "drop --input_dim")

    def dataset(self) -> dict:
        data = hnn.load_task("arm")
        return data.get_dataset(seed=self.seed, n_train=self.n_train, n_test=self.n_test,
                                arm=data.Arm((self.mass, self.mass)))


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
