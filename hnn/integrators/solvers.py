"""The integrators ``hnn.rollout`` knows, by name, with the properties tests and users rely on.

    hnn.get_solver("midpoint")   # Solver(name='midpoint', order=2, symplectic=True, needs_separable=False, ...)
    hnn.register_solver(hnn.integrators.solvers.fixed_step_solver("euler", Euler, order=1))   # Euler: a Stepper of yours
    hnn.rollout(f, x0, t_eval, method="euler", dt=0.01)

Modelled on torchdiffeq's dict of solvers and diffrax's ``order``: a method's order and
symplecticity are declared beside its name, and the tests read them (the fitted order must be
``order``; one step must be symplectic exactly when ``symplectic``), so a new integrator is a
one-place change: write it (a ``hnn.integrators.fixed_step.Stepper`` for a fixed-step one) and register it.
"""
from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass
from typing import Callable

import torch

from .adaptive import DEFAULT_SCIPY_METHOD, dop853_rollout, dopri5_rollout, scipy_rollout
from .discrete_gradient import DiscreteGradient
from .fixed_step import RK4, ImplicitStepper, Leapfrog, Midpoint, Stepper, Yoshida4, fixed_step_rollout
from .stability import LEAPFROG_LIMIT, RK4_LIMIT, YOSHIDA4_LIMIT


def _name_and_options(name: str, options: dict) -> str:
    return " ".join([name, *(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}" for k, v in options.items())])


@dataclass(frozen=True)
class Solver:
    """One integrator of ``hnn.rollout``.

    Attributes:
        name: its ``method=``.
        order: the global error is O(step^order); for an adaptive method, the order of the
            solution it advances (its error estimate is one order lower).
        symplectic: one step is a symplectic map, J^T Omega J = Omega, for a Hamiltonian field.
        needs_separable: symplectic only for a separable H = T(p) + V(q) (it reads the q and p
            halves of f at different states), as the tasks' true dynamics; not for a learned H.
            yoshida4 declares it for its default ``base='leapfrog'``; ``base='midpoint'`` lifts it.
        adaptive: steps controlled by ``rtol``/``atol`` (and ``rollout`` warns for ``rtol`` below
            100 eps of the dtype); otherwise fixed steps of at most ``dt``.
        run: ``run(f, x0, t, **options) -> (batch, len(t), dim)``, given ``rollout``'s checked
            ``x0`` ``(batch, dim)`` and float64 grid ``t`` (at least 2 times, strictly monotone).
        label: ``label(options) -> str``, how reports name the integrator run with ``options``
            (default: the name, then the options).
        energy_preserving: one step keeps the field's H exactly (to its implicit solve's
            tolerance), for any step size, not up to a bounded oscillation.
        needs_hamiltonian: it reads the field's H (an ``hnn.interface.EnergyField``, the ``field``
            of a model that declares ``conservative``), not only dx/dt: a plain field is refused.
        options: the keyword options ``rollout`` passes it; any other is a ValueError naming these
            (None: the keywords ``run`` takes).
        row_wise: each row's path depends on its own state alone, and every row reaches every call
            of ``f`` (the per-row adaptive methods given ``drop_finished=False``): the rows of many
            models can share one integration, each path as its model's own (``hnn.trainers.vmap``).
        stability_limit: the largest |lambda dt| on the imaginary axis at which a fixed step stays
            bounded (``hnn.integrators.stability``: past it ``rollout`` warns), a number or a function
            of the options (yoshida4's depends on its base); None: no limit (implicit, adaptive).
        vmap: a whole rollout runs under ``torch.vmap`` (explicit fixed steps: no step, iteration or
            test depends on a value), so a group of models rolls out as one program (``hnn.trainers.vmap``).
    """
    name: str
    order: int
    symplectic: bool
    needs_separable: bool
    adaptive: bool
    run: Callable[..., torch.Tensor]
    label: Callable[[dict], str] | None = None
    energy_preserving: bool = False
    needs_hamiltonian: bool = False
    options: tuple[str, ...] | None = None
    row_wise: bool = False
    stability_limit: float | Callable[[dict], float | None] | None = None
    vmap: bool = False

    def limit(self, options: dict) -> float | None:
        """The stability limit of this method run with ``options`` (``stability_limit``)."""
        return self.stability_limit(options) if callable(self.stability_limit) else self.stability_limit

    def accepts(self) -> tuple[str, ...]:
        """The keyword options this method takes (``options``, or ``run``'s keywords past ``f, x0, t``)."""
        return self.options if self.options is not None else _keywords(self.run)

    def check_options(self, options: dict) -> None:
        """ValueError naming this method's options when ``options`` holds another (a tolerance given to a
        fixed-step method, say, which it would otherwise ignore)."""
        unknown = sorted(set(options) - set(self.accepts()))
        if unknown:
            raise ValueError(f"method {self.name!r} takes the options {', '.join(self.accepts())}; got "
                             f"{', '.join(unknown)}: drop {'it' if len(unknown) == 1 else 'them'} or choose a "
                             "method that takes them (hnn.SOLVERS; docs/integrators.md)")

    def describe(self, options: dict) -> str:
        """The integrator's name in reports when run with ``options``, e.g. ``'RK45'`` for solve_ivp's default."""
        return self.label(options) if self.label else _name_and_options(self.name, options)


@functools.lru_cache(maxsize=None)
def _keywords(run: Callable) -> tuple[str, ...]:
    """``run``'s keywords past ``f, x0, t``, read once: its signature took a few percent of a short rollout."""
    params = list(inspect.signature(run).parameters.values())[3:]
    return tuple(p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))


# the options of every fixed-step method, and of the implicit ones' fixed-point iteration
FIXED_STEP_OPTIONS = ("dt", "max_norm", "stats")
ITERATION_OPTIONS = ("tol", "max_iter")


def fixed_step_solver(name: str, stepper: type[Stepper], order: int, symplectic: bool = False,
                      needs_separable: bool = False, energy_preserving: bool = False,
                      needs_hamiltonian: bool = False, options: tuple[str, ...] | None = None,
                      row_wise: bool = False, stability_limit=None, vmap: bool = False) -> Solver:
    """A ``Solver`` running ``stepper`` by ``hnn.integrators.fixed_step.fixed_step_rollout``; its options
    (default): ``dt``, ``max_norm``, ``stats``, and an ``ImplicitStepper``'s ``tol``, ``max_iter``."""
    run = functools.partial(fixed_step_rollout, method=name, stepper=stepper)
    if options is None:
        options = FIXED_STEP_OPTIONS + (ITERATION_OPTIONS if issubclass(stepper, ImplicitStepper) else ())
    return Solver(name, order, symplectic, needs_separable, adaptive=False, run=run,
                  energy_preserving=energy_preserving, needs_hamiltonian=needs_hamiltonian, options=options,
                  row_wise=row_wise, stability_limit=stability_limit, vmap=vmap)


def _yoshida4_limit(options: dict) -> float | None:
    """On leapfrog (its default base) an explicit method with a limit; on midpoint an implicit one without."""
    return YOSHIDA4_LIMIT if options.get("base", "leapfrog") == "leapfrog" else None


def _scipy_label(options: dict) -> str:
    return options.get("scipy_method", DEFAULT_SCIPY_METHOD)


SOLVERS: dict[str, Solver] = {solver.name: solver for solver in (
    # order 5 is RK45's, solve_ivp's default; scipy_method='DOP853' is order 8
    Solver("solve_ivp", 5, symplectic=False, needs_separable=False, adaptive=True, run=scipy_rollout,
           label=_scipy_label),
    # one step size per row (solve_ivp's is shared by the batch, the implicit methods' iterations too);
    # steps='shared' runs them on solve_ivp's terms (row_wise then no longer holds: groups.rollout_group knows)
    Solver("dopri5", 5, symplectic=False, needs_separable=False, adaptive=True, run=dopri5_rollout, row_wise=True),
    Solver("dop853", 8, symplectic=False, needs_separable=False, adaptive=True, run=dop853_rollout, row_wise=True),
    fixed_step_solver("rk4", RK4, order=4, row_wise=True, stability_limit=RK4_LIMIT, vmap=True),
    fixed_step_solver("leapfrog", Leapfrog, order=2, symplectic=True, needs_separable=True, row_wise=True,
                      stability_limit=LEAPFROG_LIMIT, vmap=True),
    fixed_step_solver("midpoint", Midpoint, order=2, symplectic=True),
    # with its default base='leapfrog'; base='midpoint' makes it symplectic for any H
    fixed_step_solver("yoshida4", Yoshida4, order=4, symplectic=True, needs_separable=True,
                      options=FIXED_STEP_OPTIONS + ("base",) + ITERATION_OPTIONS, stability_limit=_yoshida4_limit,
                      vmap=True),
    # DGNet's integrator: keeps the field's own H exactly; Gonzalez's discrete gradient, or the field's own
    fixed_step_solver("discrete_gradient", DiscreteGradient, order=2, energy_preserving=True, needs_hamiltonian=True),
)}

# the built-in symplectic methods, in registry order (a snapshot: registered ones are in SOLVERS)
SYMPLECTIC_METHODS = tuple(name for name, solver in SOLVERS.items() if solver.symplectic)


def register_solver(solver: Solver) -> Solver:
    """Add ``solver`` to ``SOLVERS``, so ``rollout(method=solver.name)`` runs it; returns it.

    Raises ``ValueError`` if the name is taken (``del SOLVERS[name]`` first to replace one).
    """
    if not isinstance(solver, Solver):
        raise TypeError(f"register_solver needs a hnn.Solver, got {type(solver).__name__}")
    if solver.name in SOLVERS:
        raise ValueError(f"a solver named {solver.name!r} is already registered")
    SOLVERS[solver.name] = solver
    return solver


def get_solver(name: str) -> Solver:
    """The registered ``Solver`` called ``name``; ``ValueError`` listing the names otherwise."""
    try:
        return SOLVERS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown method {name!r}; choose one of {sorted(SOLVERS)}") from None
