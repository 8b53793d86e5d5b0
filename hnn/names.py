"""The names a ``train.py`` offers on its command line, known before torch loads, so that
``--help`` and a flag error answer at once: the activations, the inits, the field types and the objectives.

The modules that implement them (``hnn/models/``, ``hnn/trajectory.py``) hold their own
tables; ``tests/test_kind_docs.py`` checks that these names are exactly theirs. The model kinds'
names and prose are ``hnn.kind_docs.KIND_DOCS``.
"""
NONLINEARITIES = ("tanh", "relu", "sigmoid", "softplus", "selu", "elu", "swish")
INITS = ("orthogonal", "zero_bias", "lnn", "lnn_convex")
FIELD_TYPES = ("solenoidal", "conservative", "both")
OBJECTIVES = ("derivative", "trajectory", "discrete_gradient")
DERIVATIVE_LOSSES = ("l2", "l1")
BALANCES = ("auto", "off", "rms")
UNITS = ("off", "auto", "on")
