"""Integrators: fields in, paths out. ``rollout`` is the front door; the solver registry
(``SOLVERS``, ``get_solver``, ``register_solver``) names every method with its declared
properties; ``fixed_step`` (RK4, leapfrog, Yoshida, implicit midpoint), ``discrete_gradient``,
``adaptive`` and ``dop853`` hold the methods. Nothing here knows a network: a field is any
``f(x, t) -> dx/dt``, and the optional capabilities it declares are the ``hnn.interface`` ones."""
from .fixed_step import YOSHIDA_WEIGHTS, rk4_step
from .integrate import rollout
from .solvers import SOLVERS, SYMPLECTIC_METHODS, Solver, get_solver, register_solver

__all__ = ["SOLVERS", "SYMPLECTIC_METHODS", "YOSHIDA_WEIGHTS", "Solver", "get_solver", "register_solver",
           "rk4_step", "rollout"]
