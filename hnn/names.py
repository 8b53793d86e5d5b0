"""The one list of each option's names, known before torch loads, so that ``--help`` and a flag
error answer at once: the activations, the inits, the field types, the objectives, the derivative
losses, the balances, the optimizers, the rate schedules, the dtypes, the units, the LNN's solves, the fits
and a sweep's backends and group modes.

Each name is spelled here only; the module that implements an option keeps a plain dict of it, whose
keys ``checked`` holds to this list at import (a missing or extra one fails, naming it): an activation
is a row of ``hnn.models.mlp``'s ``_NONLINEARITIES``; an init is a branch of ``hnn.models.initialize``;
a field type picks the outputs of ``hnn.models.hamiltonian.FIELD_ROWS`` (in this order); an objective
a row of ``hnn.kinds``' ``_OBJECTIVE_CLASSES`` (imported on first use); a derivative loss a row of
``hnn.training.DERIVATIVE_LOSSES``; an optimizer a row of ``hnn.trainers.loop.OPTIMIZERS``; a schedule is a
branch of ``hnn.trainers.loop.learning_rate``; a dtype is torch's of that name; a unit mode is a branch of
``hnn.units.run_scales``; an LNN solve a branch of ``hnn.models.LagrangianNN.acceleration``; a fit is a
row of ``hnn.fits.FITS``; a grouping a way ``hnn.sweeps.sweep`` trains a kind's seeds together. The model
kinds' names, classes and prose are the rows of ``hnn.kinds.MODEL_KINDS``.
"""
NONLINEARITIES = ("tanh", "relu", "sigmoid", "softplus", "selu", "elu", "swish")
INITS = ("orthogonal", "zero_bias", "lnn", "lnn_convex")
FIELD_TYPES = ("solenoidal", "conservative", "both")
OBJECTIVES = ("derivative", "trajectory", "discrete_gradient", "map")
DERIVATIVE_LOSSES = ("l2", "l1")
BALANCES = ("auto", "off", "rms")
OPTIMIZERS = ("adam", "adamw")
SCHEDULES = ("constant", "cosine")
DTYPES = ("float32", "float64")
UNITS = ("auto", "off", "on")
LNN_SOLVES = ("solve", "pinv")
BACKENDS = ("local", "ray")                 # where a sweep trains (hnn.sweeps.backends)
GROUP_MODES = ("auto", "all", "off")        # which runs a sweep trains as groups (hnn.sweeps.sweep.plan_units)
# how a run finds its weights: the training loop, or one least-squares solve (the rows of hnn.fits.FITS)
FITS = ("adam", "swim", "elm", "library", "sindy")
# how a sweep trains a kind's seeds as one group (``hnn.kinds.ModelKind.grouping``): the closed-form
# gradients of hnn.trainers.closed_form, vmap over stacked weights (hnn.trainers.vmap), or each alone
GROUPINGS = ("closed_form", "vmap", "alone")


def checked(table: dict, declared: tuple, what: str) -> dict:
    """``table`` whose keys are exactly the ``declared`` names of ``what`` (this module's list); ImportError
    naming the missing and the extra ones otherwise."""
    missing, extra = [n for n in declared if n not in table], [n for n in table if n not in declared]
    if missing or extra:
        raise ImportError(f"{what}: hnn.names lists {declared}; the table lacks {missing} and has extra {extra}: "
                          "keep the two in step")
    return table
