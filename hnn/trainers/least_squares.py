"""A prepared run (``hnn.runs.prepare``) whose weights one least-squares solve finds (``hnn.fits``): no
loop, nothing to checkpoint. Returns the stats every member of the family returns."""
from __future__ import annotations

from ..fits import solve


def solve_prepared(prep) -> dict:
    """Solve ``prep.canonical_model``'s last layer on ``prep``'s training rows, with the run's fit settings
    (``prep.specs.fit``) and the loss weights its balance resolved to; prints the fitted equation with
    ``verbose``. Returns the stats (``train_loss``, ``test_loss``, ``seconds``, ``fit``)."""
    stats = solve(prep.canonical_model, prep.x, prep.y, prep.test_x, prep.test_y, **prep.specs.fit.solve_kwargs(),
                  loss_weights=prep.options.loss_weights)
    if prep.config.verbose and "equation" in stats["fit"]:
        print(stats["fit"]["equation"])
    return stats
