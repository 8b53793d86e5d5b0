"""The one list of each option's names, known before torch loads, so that ``--help`` and a flag
error answer at once: the activations, the inits, the field types, the objectives, the derivative
losses, the balances, the optimizers, the rate schedules, the dtypes, the units, the LNN's solves, the fits
and a sweep's backends and group modes.

Each name is spelled here only; the module that implements an option keys its table from this
list and finds each implementation by a rule on the name (a missing one fails at import, naming it):
an activation is ``hnn.models.mlp``'s ``_<name>`` or else ``torch.nn.functional``'s function of
that name; an init is a branch of ``hnn.models.initialize``; a field type picks the outputs of
``hnn.models.hamiltonian.FIELD_ROWS`` (in this order); an objective ``a_b`` is the class
``ABObjective`` (``hnn.kinds.OBJECTIVES``, imported on first use); a derivative loss ``l2`` is
``hnn.training.l2_loss``; an optimizer is the ``torch.optim`` class of that name (case aside); a
schedule is a branch of ``hnn.training.learning_rate``; a dtype is torch's of that name; a unit mode is a
branch of ``hnn.units.run_scales``; an LNN solve a branch of ``hnn.models.LagrangianNN.acceleration``; a fit is a row of
``hnn.fits.FITS``. The model
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
BACKENDS = ("local", "ray")                 # where a sweep trains (hnn.backends)
GROUP_MODES = ("auto", "all", "off")        # which runs a sweep trains as groups (hnn.sweep.plan_units)
# how a run finds its weights: the training loop, or one least-squares solve (the rows of hnn.fits.FITS)
FITS = ("adam", "swim", "elm", "library", "sindy")
