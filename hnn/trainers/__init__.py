"""The ways of finding a run's weights, one family: each takes a prepared run (``hnn.policy.prepare``: its
policy already decided) and returns the same stats (``train_loss``, ``test_loss``, ``test_steps``,
``seconds``), showing progress through one reporter (``hnn.progress.Ticker``).

- ``lone``: one model, ``find_weights``: the lone loop (``loop.run_loop``; ``hnn.train`` is its front door for a
  user's arrays), or one linear solve of the last layer where a least-squares fit finds them (``hnn.fits``);
- ``closed_form``: a group of the paper's tanh-MLP kinds, the input gradient in a hand-written batched
  closed form; ``vmap``: a group of any other kind under ``torch.func.vmap``; both run ``group_loop``.

Beside them: ``rows`` (the arrays checked, a lone minibatch, a group's rows) and ``checkpoint`` (a loop's
state saved and read back). Each module loads on first use (``hnn.trainers.vmap``)."""
import importlib

_MODULES = ("checkpoint", "closed_form", "group_loop", "lone", "loop", "rows", "vmap")


def __getattr__(name: str):
    if name in _MODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
