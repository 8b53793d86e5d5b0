"""How a fit turns its least-squares problems into coefficients: a declared property of its row (``Fit.solve``).

- ``PLAIN``: each problem's least-squares solution (with its ridge), every feature kept (sampled neurons);
- ``THRESHOLDED``: SINDy's sequentially thresholded least squares (STLSQ) on the same QR factor: features
  whose coefficient is smaller than the threshold are dropped and the rest re-solved, so the model is a
  sparse sum of named terms and prints as an equation (``hnn.fits.lstsq.StreamingQR.sparse``);
- ``SINDY``: the whole model handed to pysindy's own STLSQ (``hnn.fits.sindy``), its coefficients then
  carried by our field model.

A strategy that solves the problems one at a time (``whole`` None) gives ``coefficients(solver, threshold,
ridge)`` of a ``StreamingQR``; one that fits the whole model its own way gives ``whole(model, x, dxdt,
threshold) -> dict`` (what to record). ``sparse``: the strategy keeps some features and drops the rest (the
number kept and the equation are recorded).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Solve:
    """A solve strategy (see the module): ``name``, ``line`` for readers, ``sparse``, ``whole``."""
    name: str
    line: str
    sparse: bool = False
    whole: Callable | None = None

    def coefficients(self, solver, threshold: float, ridge):
        """The coefficients ``(columns, rhs)`` of ``solver``'s problem (a ``hnn.fits.lstsq.StreamingQR``)."""
        return solver.sparse(threshold, ridge) if self.sparse else solver.solve(ridge)


def _pysindy_fit(model, x, dxdt, threshold: float) -> dict:
    from .sindy import fit_sindy     # pysindy is an optional extra: imported when a SINDy fit runs
    return fit_sindy(model, x.numpy(), dxdt.numpy(), threshold)


PLAIN = Solve("plain", "least squares, every feature kept")
THRESHOLDED = Solve("thresholded", "least squares thresholded as SINDy's STLSQ, on the problem's QR factor",
                    sparse=True)
SINDY = Solve("sindy", "pysindy's STLSQ on the whole field", sparse=True, whole=_pysindy_fit)
