"""The old name of ``hnn.fixed_step`` (and of ``hnn.solvers.SYMPLECTIC_METHODS``), kept so old imports work."""
from .fixed_step import YOSHIDA_WEIGHTS, ConvergenceError, default_tol, fixed_step_rollout  # noqa: F401
from .solvers import SYMPLECTIC_METHODS  # noqa: F401
