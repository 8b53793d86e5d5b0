"""Many runs at once: the sweep (``sweep``), where it trains (``backends``: this process, a pool, Ray) and
the flags that choose it (``flags``), runs trained as one group (``group_runs``), and a clean stop on
Ctrl-C or a kill (``stopping``). Each module loads on first use (``hnn.sweeps.sweep``): ``flags`` is
torch-free, so a command's ``--help`` answers before torch loads."""
import importlib

_MODULES = ("backends", "flags", "group_runs", "stopping", "sweep")


def __getattr__(name: str):
    if name in _MODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
