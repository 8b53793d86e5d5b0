"""Train a model of an N-bob pendulum chain on the peers' protocols (not one of the paper's tasks).

    python experiment-chain/train.py --bobs 2 --model mechanical --verbose       # CHNN's protocol
    python experiment-chain/train.py --protocol lnn --objective derivative --model mechanical

States are observed [q, qdot] (absolute angles from the downward vertical and their rates); the
Cartesian kinds (``--model constrained``, ``constrained_lagrangian``) see the same paths as the
bobs' [x, xdot] and are given the rods as their constraint graph (``Config.model_facts``).
The defaults are CHNN's training setting (Finzi et al. 2020, docs/peers.md): 800 paths of 100
states 0.03 s apart, fit by rolling out 4-step snippets (RK4, MAE), weight decay 1e-4,
learning rate 3e-3, batch 200, 256 hidden units; their 2000 epochs of 4 batches are 8000 steps.
AdamW with a cosine schedule, as theirs. Not theirs: each step draws from all 20 snippets of
every path (theirs one a path). ``analysis/peers.py`` trains and measures every model kind on it.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import setting, task_setting

HERE = Path(__file__).resolve().parent


def _state_width(text: str) -> int:
    return hnn.settings.int_at_least(2, even=True, why=" (2 per bob; --bobs sets it)")(text)


@dataclass
class Config(hnn.RunConfig):
    """The pendulum chain: N point masses on rods from a fixed pivot, observed as [q, qdot]."""
    name: str = "chain"
    input_dim: int = setting(4, "width of the state [q, qdot]: 2 per bob, set by --bobs", parse=_state_width)
    bobs: int = setting(2, "number of bobs N", parse=hnn.settings.int_at_least(1, why=" (a chain needs a bob)"))
    unit: bool = setting(False, "unit masses and rod lengths (m = l = 1) instead of CHNN's 0.6 + 0.8 U(0, 1)")
    protocol: str = setting("chnn", "chnn: paths from CHNN's start law (Finzi et al. 2020); lnn: the LNN double "
                                    "pendulum's derivative data at q ~ U[0, 2 pi], qdot ~ U[-10, 10] (Cranmer et al. "
                                    "2020; --objective derivative)", choices=("chnn", "lnn"))
    n_train: int = setting(800, "training paths (chnn) or states (lnn)", parse=hnn.settings.int_at_least(1))
    n_test: int = setting(100, "test paths (chnn) or states (lnn)", parse=hnn.settings.int_at_least(1))
    periodic: bool = task_setting("periodic", default=True)
    objective: str = "trajectory"
    optimizer: str = "adamw"
    schedule: str = "cosine"
    learn_rate: float = 3e-3
    hidden_dim: int = 256
    batch_size: int | None = 200
    total_steps: int = 8000
    print_every: int = 100    # a held-out test batch every 100 steps: the training curve of docs/peers.md
    save_dir: str = str(HERE)
    STATE: ClassVar[str] = "state [q, qdot]"
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed", "save_dir", "bobs", "unit", "protocol", "n_train", "n_test")

    def __post_init__(self):
        if self.input_dim not in (4, 2 * self.bobs):
            raise ValueError(f"input_dim={self.input_dim} does not match bobs={self.bobs}; drop --input_dim "
                             "(--bobs sets it)")
        self.input_dim = 2 * self.bobs

    def dataset(self) -> dict:
        """Observed [q, qdot], or for a kind that reads Cartesian bodies only (``data.observed_coordinates``)
        the same states as [x, xdot] of the bobs (``"state": "cartesian"``)."""
        data = hnn.load_task("chain")
        found = data.get_dataset(bobs=self.bobs, unit=self.unit, protocol=self.protocol, seed=self.seed,
                                 n_train=self.n_train, n_test=self.n_test, save_dir=self.save_dir)
        if data.observed_coordinates(self.kind) == "cartesian":
            return data.cartesian_dataset(data.chain_for(self.bobs, self.unit, self.protocol), found)
        return found

    def dataset_key(self) -> tuple:
        # angle and Cartesian runs of one chain read the same paths in different coordinates
        return super().dataset_key() + (hnn.load_task("chain").observed_coordinates(self.kind),)

    def model_facts(self) -> dict:
        """The rods as the Cartesian kinds' constraint graph."""
        chain = hnn.load_task("chain").chain_for(self.bobs, self.unit, self.protocol)
        return {"constraints": chain.constraint_graph().to_dict()}


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
