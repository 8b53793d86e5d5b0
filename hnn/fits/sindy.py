"""SINDy as a rung: pysindy (an optional extra, ``pip install -e ".[sindy]"``) fitted to dx/dt
as a user would fit it first, its coefficients then carried by our own field model.

pysindy fits dx/dt = Theta(x) Xi: ``PolynomialLibrary(degree)`` on every column and ``FourierLibrary
(frequencies)`` on the positions q, its ``STLSQ(threshold)`` with its other defaults (ridge alpha 0.05,
unbiased refit), ``model.fit(x, t, x_dot=dxdt)``. Each of its library's columns is one of the terms of
our ``FittedField``'s library (``hnn.fits.features.terms(..., 'field', products=False)``), matched by
their values at probe states; Xi goes there, and the match is checked against ``model.predict``. The run
then rolls out, saves and reloads without pysindy, and is measured by our metrics, never by its own.
"""
from __future__ import annotations

import numpy as np
import torch

from .equations import column_names
from .features import Library
from .models import FittedField

MATCH = 1e-9        # a pysindy column and our term agree to this (relative) at every probe state


class SindyLibrary(Library):
    """SINDy's library as a user would write it in pysindy: dx/dt's terms (the ``field`` form), polynomials of
    every column and sines and cosines of q, no products of the two (the ``sindy`` fit's features)."""
    forms = ("field",)
    products = False


def pysindy():
    """The pysindy module, or a ValueError naming the extra that installs it."""
    try:
        import pysindy as ps
    except ImportError as err:
        raise ValueError("--fit sindy needs pysindy, an optional extra: pip install -e '.[sindy]' "
                         f"({err})") from None
    return ps


def version() -> str | None:
    """pysindy's version, or None where it is not installed."""
    try:
        import pysindy as ps
    except ImportError:
        return None
    return ps.__version__


def _library(ps, library: Library, n: int):
    degree = int(library.powers.sum(dim=1).max())
    frequencies = int(library.trig[:, 2].max())
    polynomial = ps.PolynomialLibrary(degree=degree)
    if frequencies == 0:
        return polynomial
    return ps.GeneralizedLibrary([polynomial, ps.FourierLibrary(n_frequencies=frequencies)],
                                 inputs_per_library=[list(range(2 * n)), list(range(n))])


def _match(theirs: np.ndarray, ours: np.ndarray) -> list[int]:
    """For each column of ``theirs`` ``(probes, F)``, the column of ``ours`` ``(probes, P)`` with its values."""
    index = []
    for f in range(theirs.shape[1]):
        gap = np.abs(ours - theirs[:, f:f + 1]).max(axis=0) / max(np.abs(theirs[:, f]).max(), 1.0)
        k = int(gap.argmin())
        if gap[k] > MATCH:
            raise RuntimeError(f"pysindy's library column {f} is none of our field library's terms (closest "
                               f"{gap[k]:.2g} apart): its library changed; hnn.fits.sindy must learn its terms")
        index.append(k)
    return index


def fit_sindy(model: FittedField, x: np.ndarray, dxdt: np.ndarray, threshold: float) -> dict:
    """Fit ``model`` (a ``FittedField`` over the SINDy library, ``hnn.fits.build(fit='sindy')``) with pysindy
    on states ``x`` and their ``dxdt`` ``(rows, 2n)``; returns what to record (pysindy's version, its terms)."""
    if not (isinstance(model, FittedField) and model.features.formula):
        raise ValueError("the sindy fit fills a FittedField over the field library: build it with "
                         "hnn.fits.build(ModelSpec(kind='baseline', fit='sindy', ...))")
    ps = pysindy()
    n = x.shape[1] // 2
    sindy = ps.SINDy(optimizer=ps.STLSQ(threshold=threshold), feature_library=_library(ps, model.features, n))
    sindy.fit(x, t=1.0, x_dot=dxdt, feature_names=column_names(x.shape[1]))     # t: unused beside x_dot
    xi = np.asarray(sindy.coefficients(), dtype=np.float64)                      # (dim, F)
    low, high = x.min(axis=0), x.max(axis=0)
    probes = np.random.default_rng(0).uniform(low - 0.5, high + 0.5, size=(64, x.shape[1]))
    theirs = np.asarray(sindy.feature_library.transform(probes), dtype=np.float64)
    with torch.no_grad():
        ours = model.features(torch.as_tensor(probes)).numpy()
        coef = torch.zeros_like(model.coef)
        for f, k in enumerate(_match(theirs, ours)):
            coef[k] += torch.as_tensor(xi[:, f])
        model.coef.copy_(coef)
        model.bias.zero_()
        ours_pred = model.time_derivative(torch.as_tensor(probes)).numpy()
    theirs_pred = np.asarray(sindy.predict(probes), dtype=np.float64)
    if not np.allclose(ours_pred, theirs_pred, rtol=1e-8, atol=1e-8 * max(1.0, np.abs(theirs_pred).max())):
        raise RuntimeError("the field rebuilt from pysindy's coefficients does not predict what pysindy does")
    return {"package": f"pysindy {ps.__version__}", "sindy_terms": [str(name) for name in sindy.get_feature_names()],
            "threshold": threshold}
