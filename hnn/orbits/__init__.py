"""The orbit tasks' shared physics and config: the gravity of n bodies and its datasets (``nbody``), the
close-encounter thresholds the data and the rollouts keep (``encounters``) and the 2- and 3-body tasks'
``OrbitConfig`` (``config``). Each module loads on first use (``hnn.orbits.config``): ``config`` and
``encounters`` are torch-free, so a task's ``--help`` answers before torch loads."""
import importlib

_MODULES = ("config", "encounters", "nbody")


def __getattr__(name: str):
    if name in _MODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
