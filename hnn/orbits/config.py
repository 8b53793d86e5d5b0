"""The orbit tasks' run config, without torch: a ``train.py``'s ``--help`` reads it (its bodies, and the
close-encounter thresholds of ``hnn.orbits.encounters``) before the gravity code (``hnn.orbits.nbody``) loads."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..bodies import Bodies
from ..config import RunConfig
from ..settings import setting
from .encounters import MIN_SEPARATION, TASK_MIN_SEPARATION



@dataclass
class OrbitConfig(RunConfig):
    """The orbit tasks' config: ``min_separation`` beside the shared fields; a subclass names its
    task (``TASK``, the folder whose ``get_dataset`` it calls) and its defaults."""
    min_separation: float = setting(TASK_MIN_SEPARATION, "redraw orbits whose bodies come closer than this (close "
                                    f"encounters); 0 keeps them all, as the original did; {MIN_SEPARATION} gives "
                                    "the cleaned dataset", parse=float)
    TASK: ClassVar[str] = ""
    # the state's layout (the original's: every body's x, then every body's y, in each half); a subclass
    # declares its count
    BODIES: ClassVar[Bodies | None] = None
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed", "save_dir", "min_separation")

    def model_facts(self) -> dict:
        """The task's bodies (``hnn.bodies.Bodies``), which the pair kind reads."""
        return {} if self.BODIES is None else {"bodies": self.BODIES.to_dict()}

    def dataset(self) -> dict:
        from ..tasks import load_task
        return load_task(self.TASK).get_dataset(seed=self.seed, save_dir=self.save_dir,
                                                min_separation=self.min_separation)
