"""Fits: a model's weights by one linear least-squares solve instead of the training loop.

A fit is how a run finds its weights (``--fit``, ``hnn.RunConfig.fit``): ``adam``, the loop, or a solve
of dx/dt over features that are drawn or written out, never trained (``FITS``: ``swim``, ``elm``,
``library``, ``sindy``). The symplectic gradient J grad H of H = phi(x) . c is linear in c, so fitting
dx/dt is one least-squares problem, conservative by construction. A fitted run saves, reloads and rolls
out as any run; its model is an ``hnn.Model`` of its kind (``hnn``, ``separable``, ``baseline``).

- ``registry``: the rows (``FITS``): each fit's kinds (``check``), feature sets, sampler and solve; the untrained
  model (``build``);
- ``base``: the features interface (``Features``): a new feature set is one module and one row;
- ``solves``: how a row's problems become coefficients (plain, thresholded as STLSQ, pysindy's);
- ``features``: sampled tanh neurons and the library's terms, values and gradients in closed form;
- ``sampling``: where sampled neurons come from (SWIM's pairs of points, ELM's random draws);
- ``models``: the fitted models and their least-squares problems;
- ``equations``: a library fit's equation, in its own coordinates or the user's columns and units (``Frame``);
- ``radial``: the pair kind's fit, V(r) over a radial library or sampled radial neurons, and inverse masses;
- ``lstsq``: the chunked QR solve in float64 and SINDy's sequential thresholding;
- ``fitting``: ``solve`` (a run's fit) and ``fit_least_squares`` (``hnn.fit_least_squares``);
- ``sindy``: pysindy (optional extra ``sindy``) wrapped as a field model.
"""
from . import equations, sindy
from .equations import Frame, equation
from .fitting import fit_least_squares, solve
from .models import FittedField, FittedHNN, FittedSeparable
from .registry import FITS, LINEAR_KINDS, Fit, build, check, check_config, get_fit

__all__ = ["FITS", "LINEAR_KINDS", "Fit", "FittedField", "FittedHNN", "FittedSeparable", "Frame", "build", "check",
           "check_config", "equation", "equations", "fit_least_squares", "get_fit", "sindy", "solve"]
