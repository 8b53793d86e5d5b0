"""A lone prepared run's weights (``hnn.policy.prepare``: its policy of units, balance, subset, seed and
threads already decided): ``find_weights`` takes the way its config names, one least-squares solve
(``solve_prepared``, ``hnn.fits``: no loop, nothing to checkpoint) or the lone loop (``train_prepared``: its
arrays checked here and handed with its objective's loss to ``hnn.trainers.loop.run_loop``). Each returns the
stats every member of the family returns."""
from __future__ import annotations

from ..fits import solve
from .loop import run_loop
from .rows import checked_pair, warn_off_scale


def find_weights(prep, checkpoint=None, on_step=None) -> dict:
    """The weights of ``prep`` found the way its config says (``prep.fit``): one solve where a least-squares
    fit finds them (``checkpoint`` and ``on_step`` unused: nothing to resume, no steps), else the lone loop
    (``train_prepared``). Returns the stats."""
    if prep.fit.solved:
        return solve_prepared(prep)
    return train_prepared(prep, checkpoint=checkpoint, on_step=on_step)


def solve_prepared(prep) -> dict:
    """Solve ``prep.canonical_model``'s last layer on ``prep``'s training rows, with the run's fit settings
    (``prep.specs.fit``) and the loss weights its balance resolved to; prints the fitted equation with
    ``verbose``. Returns the stats (``train_loss``, ``test_loss``, ``seconds``, ``fit``)."""
    stats = solve(prep.canonical_model, prep.x, prep.y, prep.test_x, prep.test_y, **prep.specs.fit.solve_kwargs(),
                  loss_weights=prep.options.loss_weights)
    if prep.config.verbose and "equation" in stats["fit"]:
        print(stats["fit"]["equation"])
    return stats


def train_prepared(prep, checkpoint=None, on_step=None, **overrides) -> dict:
    """Train ``prep.canonical_model`` on ``prep``'s training rows (``x``, ``y``) with its loop settings and its
    objective's options (``prep.train_kwargs``; ``overrides``: a benchmark's steps, say), keeping
    ``checkpoint`` (a file; None: none). ``on_step(done, total)``: ``run_loop``'s. Returns
    ``hnn.train``'s stats."""
    kwargs = prep.train_kwargs(**overrides)
    model, loss = prep.canonical_model, kwargs.pop("loss")
    param = next(model.parameters())
    # a custom loss owns its arrays' layout (e.g. flattened trajectory snippets): rows, not widths, are checked
    kw = dict(width=getattr(model, "input_dim", None) if loss is None else None, dtype=param.dtype, device=param.device)
    x, y = checked_pair("x", prep.x, prep.y, kw)
    test = checked_pair("test_x", prep.test_x, prep.test_y, kw) if prep.test_x is not None else (None, None)
    derivative = loss is None
    loss = prep.options.loss_of(model) if loss is None else loss
    if derivative and prep.scales is None:     # trained as given: say so where the data lie far from unit scale
        warn_off_scale(x, y, model, stacklevel=5)
    for key in ("predict", "derivative_loss", "loss_weights", "units", "balance"):       # decided: in the loss already
        kwargs.pop(key)
    # its own lines (verbose), or a caller that shows progress its own way (on_step): no bar
    progress = False if kwargs["verbose"] or on_step is not None else None
    return run_loop(model, loss, x, y, *test, checkpoint=checkpoint, on_step=on_step, progress=progress, **kwargs)
