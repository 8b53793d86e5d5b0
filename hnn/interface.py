"""The model interface: what every model kind declares, and what every consumer reads.

A model is an ``hnn.Model``: an ``nn.Module`` with ``time_derivative(x)`` on its own state ``x``
of shape ``(batch, dim)``, and class-level declarations instead of abilities found by probing:

- ``coordinates``: the state its ``time_derivative`` reads, a key of ``COORDINATES``
  (``'canonical'`` [q, p], ``'velocity'`` [q, qdot], ``'cartesian'`` [x, xdot] of bodies,
  ``'cartesian_canonical'`` [x, p] of bodies, ``'latent'`` a pixel model's learned [q, p]).
- ``takes``: other observed coordinates it reads as its own state without a map, each with the
  assumption that makes that right (the paper's HNN reads [q, qdot] as [q, p]: unit mass).
- ``maps``: observed coordinates it maps into its own state and back, through
  ``state_from_observed(z)``, ``observed_from_state(x)`` and ``observed_time_derivative(z)``
  (a mechanical HNN: [q, qdot] -> [q, M(q) qdot] by its learned mass matrix).
- ``conservative``: it has ``hamiltonian(x)``, an H its flow conserves.
  Its ``field`` is then an ``EnergyField``: the flow with its H and the structure matrix S of
  dx/dt = S grad H, which an energy-preserving solver (``'discrete_gradient'``) reads.
- ``separable``: that H is T(p) + V(q), with ``kinetic_gradient(p)`` and ``potential_gradient(q)``;
  its ``field`` is then a ``SplitField`` that explicit symplectic solvers evaluate half by half.
- ``dissipative``: its flow loses energy on purpose (no energy drift is measured).
- ``steps``: a learned map, not a field: ``step(x)`` is its state ``dt`` later (its declared step,
  the data's, an attribute of the instance), and ``inverse(x)`` its state ``dt`` earlier; it has no
  ``time_derivative``. Its ``field`` is then a ``StepMap``, which ``hnn.rollout`` steps on ``t_eval``
  of multiples of ``dt`` (``hnn.models.maps``: the SympNets and HenonNets).

Consumers (objectives, the integrators, the studies) read these and call ``state_from``,
``observed_from`` and ``observed_field`` with the coordinates a dataset declares
(``dataset["state"]``); a pair that does not fit is one ``ValueError`` naming the fix.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import torch
from torch import nn

from .modes import in_model_axis

COORDINATES = {
    "canonical": "[q, p]: generalized positions and their canonical momenta",
    "velocity": "[q, qdot]: generalized positions and their velocities (as observed)",
    "cartesian": "[x, xdot]: Cartesian positions of the bodies, flattened, and their velocities (as observed)",
    "cartesian_canonical": "[x, p]: Cartesian positions of the bodies, flattened, and their momenta",
    "latent": "[q, p]: a pixel model's learned latent coordinates",
}

# what a kind that reads [q, p] assumes when it is given observed [q, qdot] as they are
UNIT_MASS = {"velocity": "reads qdot as p: Hamilton's equations hold for it only where the mass matrix is the "
                         "identity in these coordinates; on observed velocities choose mechanical"}
# a black-box field reads any state: it assumes nothing about what the halves are
ANY_STATE = {name: "a black-box field: no structure assumed" for name in COORDINATES}


def gradient_of(f: Callable, x: torch.Tensor, create_graph: bool | None = None) -> torch.Tensor:
    """d f/dx by autograd at each row, ``(batch, dim)``, of ``f``: ``(batch, dim) -> (batch,)`` (rows
    independent): an H's gradient, the one autograd input gradient every network without a closed
    form uses. ``create_graph`` (default: whether grad mode is on) keeps the graph, so the result can
    be differentiated again (training through a field); ``x`` itself stays in the graph only then."""
    if in_model_axis():         # under vmap over models: autograd.grad cannot run there, torch.func's can
        return torch.func.grad(lambda x_in: f(x_in).sum())(x)
    if create_graph is None:
        create_graph = torch.is_grad_enabled()
    with torch.enable_grad():
        x_in = x if (create_graph and x.requires_grad) else x.detach().requires_grad_(True)
        return torch.autograd.grad(f(x_in).sum(), x_in, create_graph=create_graph)[0]


def carries_energy(f) -> bool:
    """Whether the field ``f`` carries its H (an ``EnergyField`` with a ``hamiltonian``), so that
    solvers which read H (``needs_hamiltonian``) apply to it."""
    return isinstance(f, EnergyField) and f.hamiltonian is not None


class EnergyField:
    """A field dx/dt = S grad H(x) that carries its H, for solvers that read H (``'discrete_gradient'``).

    Callable as the field ``whole`` ``(batch, dim) -> (batch, dim)``. ``hamiltonian``:
    ``(batch, dim) -> (batch,)``; ``structure``: the skew ``(dim, dim)`` S (None: the canonical
    [[0, I], [-I, 0]] of the state's width); ``discrete_gradient``: an exact discrete gradient
    ``(x0, x1) -> (batch, dim)`` in closed form where the model has one (None: the solver builds
    Gonzalez's from ``hamiltonian``). Without ``hamiltonian`` it is a plain field. ``numpy``: the field
    on numpy states ``(rows, dim)`` as a new array, or None for states it does not serve (a solver
    stepping in numpy then calls the field): the same bits without the tensor conversions a call costs.
    """

    def __init__(self, whole: Callable, hamiltonian: Callable | None = None, structure: torch.Tensor | None = None,
                 discrete_gradient: Callable | None = None, numpy: Callable | None = None):
        self.whole, self.hamiltonian, self.structure = whole, hamiltonian, structure
        self.discrete_gradient, self.numpy = discrete_gradient, numpy

    def __call__(self, x: torch.Tensor, t=None) -> torch.Tensor:
        return self.whole(x)


class SplitField(EnergyField):
    """A separable field dx/dt = (dT/dp, -dV/dq) given by its two halves, each ``(batch, n)`` -> ``(batch, n)``.

    Callable as a whole field; explicit symplectic steppers (``leapfrog``, ``yoshida4``) call
    ``kinetic_gradient`` and ``potential_gradient`` alone where a stage reads one half.
    ``energy``: ``EnergyField``'s keywords (its H T + V, ...).
    """

    def __init__(self, whole: Callable, kinetic_gradient: Callable, potential_gradient: Callable, **energy):
        super().__init__(whole, **energy)
        self.kinetic_gradient, self.potential_gradient = kinetic_gradient, potential_gradient


class StepMap:
    """What a learned map's ``field`` is (a model that declares ``steps``): ``step`` ``(batch, dim) ->
    (batch, dim)``, the state ``dt`` later; ``inverse``, ``dt`` earlier (None: the map has none);
    ``dt``, its step. ``hnn.rollout`` steps it on ``t_eval`` of multiples of ``dt``. Not a field:
    calling it as dx/dt is a TypeError naming the fix."""

    def __init__(self, step: Callable, dt: float, inverse: Callable):
        self.step, self.dt, self.inverse = step, dt, inverse

    def __call__(self, x: torch.Tensor, t=None) -> torch.Tensor:
        raise TypeError(f"a learned map has no field dx/dt to integrate: it steps x -> x(t + {self.dt:g}) itself; "
                        "roll it out with hnn.rollout(model, x0, t_eval) on t_eval of multiples of its dt")


def step_map_of(f) -> StepMap | None:
    """The ``StepMap`` of ``f`` (a ``StepMap``, a model that declares ``steps`` or one of its bound
    methods), or None for a field."""
    owner = getattr(f, "__self__", f)
    if isinstance(f, StepMap):
        return f
    return owner.field if isinstance(owner, Model) and owner.steps else None


class Model(nn.Module):
    """The interface of every model kind; subclasses set the declarations and ``time_derivative``
    (a learned map, ``steps``: ``step``, ``inverse`` and ``dt`` instead).

    Groups run a kind under ``torch.vmap`` (``hnn.trainers.vmap``: many seeds' models as one batched model,
    in training and in rollouts), where a tensor has no value to branch on: any check that reads one
    (``bool(t)``, ``t.item()``, ``if (x > 0).any()``, a shape chosen by a mask) must be skipped where
    ``hnn.modes.in_model_axis()`` is true, as ``hnn.fits.features.Library.gradient`` does. A kind that
    groups is tested through a group by ``tests/test_stacked.py``.
    """

    coordinates: ClassVar[str] = "canonical"
    takes: ClassVar[dict[str, str]] = {}
    maps: ClassVar[tuple[str, ...]] = ()
    conservative: ClassVar[bool] = False
    separable: ClassVar[bool] = False
    dissipative: ClassVar[bool] = False
    steps: ClassVar[bool] = False
    input_dim: int

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        for name in (cls.coordinates, *cls.takes, *cls.maps):
            if name not in COORDINATES:
                raise TypeError(f"{cls.__name__} declares coordinates {name!r}; known: {sorted(COORDINATES)}")
        if cls.separable and not all(callable(getattr(cls, name, None)) for name in ("kinetic_gradient",
                                                                                    "potential_gradient")):
            raise TypeError(f"{cls.__name__} declares separable=True: give it kinetic_gradient(p) and "
                            "potential_gradient(q)")
        if cls.conservative and cls.hamiltonian is Model.hamiltonian:
            raise TypeError(f"{cls.__name__} declares conservative=True: give it hamiltonian(x)")
        if cls.steps and not all(callable(getattr(cls, name, None)) for name in ("step", "inverse")):
            raise TypeError(f"{cls.__name__} declares steps=True: give it step(x) and inverse(x), its state dt "
                            "later and earlier")

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        """``dx/dt`` ``(batch, dim)`` at the model's own states ``x`` ``(batch, dim)``."""
        raise NotImplementedError(f"{type(self).__name__} must implement time_derivative")

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """The learned H ``(batch,)`` at ``x`` ``(batch, dim)``; only where ``conservative``."""
        raise TypeError(f"{type(self).__name__} learns no Hamiltonian (conservative=False); choose a conservative "
                        "kind such as hnn, separable or mechanical")

    def structure(self) -> torch.Tensor | None:
        """The skew S with ``time_derivative(x) = grad H(x) @ S.T`` where ``conservative``; None: the
        canonical [[0, I], [-I, 0]] of the state's width (Hamilton's equations)."""
        return None

    def exact_discrete_gradient(self) -> Callable | None:
        """A closed-form discrete gradient ``(x0, x1) -> (batch, dim)`` of H, where the model has one:
        grad-bar H(x0, x1) . (x1 - x0) = H(x1) - H(x0), grad-bar H(x, x) = grad H(x). None by default
        (an energy-preserving solver then builds Gonzalez's from ``hamiltonian``)."""
        return None

    def numpy_time_derivative(self) -> Callable | None:
        """``dx/dt`` on numpy states as the model's ``EnergyField.numpy`` (a new array, or None where it does
        not serve the states); None by default: solvers call ``time_derivative``."""
        return None

    @property
    def field(self) -> Callable:
        """What an integrator steps: ``time_derivative`` (an ``EnergyField`` without H where the model has a
        numpy call, ``numpy_time_derivative``); an ``EnergyField`` carrying H when ``conservative``, a
        ``SplitField`` (an ``EnergyField`` too) when ``separable``; a learned map's ``StepMap`` when it ``steps``."""
        if self.steps:
            return StepMap(self.step, self.dt, self.inverse)
        if not self.conservative:       # a plain field; with its numpy call where it has one (solvers in numpy)
            numpy = self.numpy_time_derivative()
            return self.time_derivative if numpy is None else EnergyField(self.time_derivative, numpy=numpy)
        energy = {"hamiltonian": self.hamiltonian, "structure": self.structure(),
                  "discrete_gradient": self.exact_discrete_gradient(), "numpy": self.numpy_time_derivative()}
        if self.separable:
            return SplitField(self.time_derivative, self.kinetic_gradient, self.potential_gradient, **energy)
        return EnergyField(self.time_derivative, **energy)

    # -- observed coordinates ----------------------------------------------------------------------

    def relation(self, observed: str) -> str:
        """How this model reads states in ``observed`` coordinates: ``'own'`` (its state, or one it
        takes as its state) or ``'mapped'`` (through ``state_from_observed``); else ValueError."""
        if observed == self.coordinates or observed in self.takes:
            return "own"
        if observed in self.maps:
            return "mapped"
        if observed not in COORDINATES:
            raise ValueError(f"unknown coordinates {observed!r}; known: {sorted(COORDINATES)}")
        readable = sorted({self.coordinates, *self.takes, *self.maps})
        raise ValueError(f"{type(self).__name__} reads {COORDINATES[self.coordinates]} and cannot be fit to states "
                         f"in {observed!r} coordinates ({COORDINATES[observed]}); it reads {readable}: choose "
                         "another --model (hnn.MODEL_KINDS declares what each reads)")

    def state_from(self, z: torch.Tensor, observed: str) -> torch.Tensor:
        """The model's own state for observed states ``z`` ``(batch, dim)`` in ``observed`` coordinates."""
        return z if self.relation(observed) == "own" else self.state_from_observed(z)

    def observed_from(self, x: torch.Tensor, observed: str) -> torch.Tensor:
        """Observed states in ``observed`` coordinates for the model's own states ``x`` ``(batch, dim)``."""
        return x if self.relation(observed) == "own" else self.observed_from_state(x)

    def observed_field(self, observed: str) -> Callable:
        """``z -> dz/dt`` on observed states in ``observed`` coordinates, along the model's flow."""
        return self.time_derivative if self.relation(observed) == "own" else self.observed_time_derivative

    def state_from_observed(self, z: torch.Tensor) -> torch.Tensor:
        """Own state from an observed one, for the coordinates in ``maps``."""
        raise NotImplementedError(f"{type(self).__name__} declares maps={self.maps} but no state_from_observed")

    def observed_from_state(self, x: torch.Tensor) -> torch.Tensor:
        """Observed state from the model's own, for the coordinates in ``maps``."""
        raise NotImplementedError(f"{type(self).__name__} declares maps={self.maps} but no observed_from_state")

    def observed_time_derivative(self, z: torch.Tensor) -> torch.Tensor:
        """d/dt of an observed state along the model's flow, for the coordinates in ``maps``."""
        raise NotImplementedError(f"{type(self).__name__} declares maps={self.maps} but no observed_time_derivative")


def observed_coordinates(dataset: dict) -> str:
    """The coordinates of ``dataset``'s states (``dataset["state"]``, a key of ``COORDINATES``; default ``'canonical'``)."""
    return dataset.get("state", "canonical")


def declared(model) -> Model:
    """``model`` itself if it is an ``hnn.Model`` (whose declarations a consumer reads), else a
    TypeError naming the fix."""
    if not isinstance(model, Model):
        raise TypeError(f"{type(model).__name__} is not an hnn.Model: subclass hnn.Model and declare its "
                        "coordinates, conservative, separable (see hnn/interface.py)")
    return model
