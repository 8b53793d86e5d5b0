"""The fits: how a run finds its model's weights, one row each, everything about a fit in its row.

``adam`` is the training loop (``hnn.train``); every other row is one linear least-squares solve in
float64 (``hnn.fits.fitting``) over features that are drawn or written out, never trained: the fitted
field is linear in the last weights, so fitting dx/dt is one problem. A row declares the model kinds it
applies to, the feature sets it combines (``hnn.fits.base.Features``), how their neurons are drawn, its
solve (``hnn.fits.solves``), the package it needs, and its prose; ``check`` refuses a run the fit cannot
serve, naming the fix; ``build`` makes the untrained model of a run's ``ModelSpec`` (it also rebuilds a
saved run's model for ``hnn.load_run``).

A new feature set is one module (its ``Features``) and one row here (or its class added to a row's
``features``): ``build`` asks the row's sets for the form the kind reads (``hnn.fits.base.made``), and
the solve does what the row and the features declare.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..names import FITS as NAMES
from ..specs import ModelSpec
from .base import made
from .features import Library, TanhFeatures
from .models import FittedField, FittedHNN, FittedSeparable
from .radial import FittedPair, RadialLibrary
from .sampling import elm, swim
from .sindy import SindyLibrary
from .solves import PLAIN, SINDY, THRESHOLDED, Solve

# the fitted models, one a kind whose field is linear in the last layer's weights: H = phi . c (hnn), T + V
# (separable), phi C (baseline), and the pair sum of V(r) = phi(r) . c with inverse masses (pairwise)
FITTED_MODELS = (FittedHNN, FittedSeparable, FittedField, FittedPair)
LINEAR_KINDS = tuple(model.kind for model in FITTED_MODELS)


@dataclass(frozen=True)
class Fit:
    """A fit: ``kinds`` it applies to (None: every kind); ``features``: the feature sets it combines
    (``hnn.fits.base.Features`` classes; a kind's model takes the first that stands for the form it reads:
    a library of x's terms, or of a pair distance's); ``sampler``: how a drawn set's neurons come from
    the data, ``(z (rows, in_dim), width, rng, values) -> (weight, bias)`` (``hnn.fits.sampling``);
    ``solve``: how the least-squares problems become coefficients (``hnn.fits.solves``; None: trained by
    Adam); ``only``: where the row takes fewer kinds than the linear ones, why (the fix: one of its
    ``kinds``); ``package``: the optional package it imports (pip extra ``extra``); ``line``: what
    it is, for readers; ``marker``: its points' marker in the studies' plots (a kind's colour beside it says
    which model)."""
    name: str
    line: str
    kinds: tuple[str, ...] | None = LINEAR_KINDS
    features: tuple = ()
    sampler: Callable | None = None
    solve: Solve | None = None
    only: str | None = None
    package: str | None = None
    extra: str | None = None
    marker: str = "o"

    def __post_init__(self):
        drawn = any(features.drawn for features in self.features)
        if (self.solve is None) != (not self.features) or drawn != (self.sampler is not None):
            raise ValueError(f"fit {self.name!r}: a solved fit names its features and its solve, and a sampler "
                             f"exactly where its features are drawn; got features={self.features}, "
                             f"sampler={self.sampler}, solve={self.solve}")

    @property
    def solved(self) -> bool:
        """One linear solve (not a training loop): the run is a fit of dx/dt, in float64."""
        return self.solve is not None

    @property
    def prints_equation(self) -> bool:
        """Its models are sums of written-out terms (ours or SINDy's) that print as equations."""
        return self.solved and all(features.formula for features in self.features)


FITS: dict[str, Fit] = {
    "adam": Fit("adam", "the training loop: Adam on the kind's objective (hnn.train), the paper's", kinds=None),
    "swim": Fit("swim", "a hidden layer of --hidden_dim tanh neurons, each from a pair of training states "
                        "(SWIM, Rahma, Datar & Dietrich 2024), and the last layer by least squares",
                features=(TanhFeatures,), sampler=swim, solve=PLAIN, marker="s"),
    "elm": Fit("elm", "a hidden layer of --hidden_dim tanh neurons drawn at random (an extreme learning machine), "
                      "and the last layer by least squares", features=(TanhFeatures,), sampler=elm, solve=PLAIN,
               marker="v"),
    "library": Fit("library", "H (or, for the baseline, dx/dt) as a sparse sum of terms: polynomials of q and p, "
                              "sines and cosines of q and their products with p (for the pair kind, powers of the "
                              "distance r); least squares thresholded as SINDy's STLSQ, so the model prints as an "
                              "equation", features=(Library, RadialLibrary), solve=THRESHOLDED, marker="^"),
    "sindy": Fit("sindy", "pysindy's SINDy: dx/dt = Theta(x) Xi over polynomials and sines and cosines of q, its "
                          "STLSQ; no H (--model baseline); rolled out and measured as our models are",
                 kinds=("baseline",), features=(SindyLibrary,), solve=SINDY,
                 only="fits dx/dt = Theta(x) Xi with no H", package="pysindy", extra="sindy",
                 marker="D"),
}
if tuple(FITS) != NAMES:
    raise ImportError(f"hnn.names.FITS lists {NAMES}, hnn.fits.FITS has rows {tuple(FITS)}")


def get_fit(name: str) -> Fit:
    """The row of fit ``name``, or a ValueError naming the fits."""
    if name not in FITS:
        raise ValueError(f"unknown fit {name!r}; choose one of {', '.join(FITS)}")
    return FITS[name]


def check(kind: str, fit: str, *, coordinates: str = "canonical", objective: str = "derivative",
          use_rk4: bool = False, derivative_loss: str = "l2", input_noise: float = 0.0) -> Fit:
    """The row of ``fit`` if it can fit a run of model ``kind`` with these settings, else a ValueError
    naming the problem and the fix (torch-free: a ``train.py`` refuses before any data is built)."""
    row = get_fit(fit)
    if not row.solved:
        return row
    flag = f"--fit {fit}"
    if coordinates == "latent":
        raise ValueError(f"{flag}: the pixel task learns its latent [q, p] with its autoencoder, which no linear "
                         "solve can find (the features would need coordinates the frames do not give); train it "
                         "with --fit adam")
    if kind not in row.kinds:
        why = (f"{row.only}: pass --model {' or '.join(row.kinds)}" if row.only else
               f"solves the last weights of the {', '.join(row.kinds)} kinds, whose field is linear in them; "
               f"the {kind} kind's is not: train it with --fit adam, or pick one of those kinds")
        raise ValueError(f"{flag} {why}")
    if objective != "derivative" or use_rk4:
        raise ValueError(f"{flag} fits dx/dt at each state (--objective derivative without --use_rk4): the rollout "
                         "of a path is not linear in the weights; drop "
                         + ("--use_rk4" if use_rk4 else f"--objective {objective}"))
    if derivative_loss != "l2":
        raise ValueError(f"{flag} solves the squared error (l2); --derivative_loss {derivative_loss} is the loop's: "
                         "drop it")
    if input_noise:
        raise ValueError(f"{flag} fits the data as they are; --input_noise {input_noise:g} is the training loop's "
                         "augmentation: drop it")
    return row


def check_config(config, coordinates: str = "canonical") -> Fit:
    """``check`` of an ``hnn.RunConfig``'s fit, kind and objective settings; ``coordinates``: those its kind's
    model reads (``hnn.MODEL_KINDS[config.kind].coordinates``)."""
    return check(config.kind, getattr(config, "fit", "adam"), coordinates=coordinates, objective=config.objective,
                 use_rk4=config.use_rk4, derivative_loss=config.derivative_loss,
                 input_noise=getattr(config, "input_noise", 0.0))


def fitted_model(kind: str):
    """The fitted model class of ``kind`` (one of ``LINEAR_KINDS``), or a ValueError naming them."""
    for model in FITTED_MODELS:
        if model.kind == kind:
            return model
    raise ValueError(f"no fitted model of kind {kind!r}; a least-squares fit makes {', '.join(LINEAR_KINDS)}")


def build(spec: ModelSpec):
    """The untrained fitted model of ``spec`` (its ``fit``, ``kind``, ``input_dim``, ``hidden_dim``, the
    library's ``library_degree`` and ``library_frequencies``, the pair kind's ``bodies``): the kind's fitted
    model (``FITTED_MODELS``) over the row's features for the forms it reads; zeros until
    ``hnn.fits.fitting.solve`` fits it (``hnn.kinds.model_from_spec`` builds it for a run, and again for
    ``hnn.load_run``)."""
    row = check(spec.kind, spec.fit)
    return fitted_model(spec.kind).from_spec(spec, lambda form, in_dim: made(row.features, spec, form, in_dim))
