"""The registry of model kinds and objectives: one row a kind, everything about it in that row.

A run's config names its kind (``RunConfig.kind``, saved in ``args.json`` as ``"kind"``) and its
objective (``RunConfig.objective``); ``model_from_args`` reads a run's args into a ``ModelSpec``
(the declared fields a builder may read) and builds the kind's untrained model from it (its init
draws from torch's global generator, seeded by the run), which also rebuilds a saved run's model.
What a kind *is* (its coordinates, whether it conserves an H, separable, dissipative) is declared
once, by its model class (``hnn.Model``); the row names that class, and carries the kind's prose
(``KindDoc``: ``--model``'s help, the README's list and docs/python.md's paragraphs), its builder,
objective and colour, so ``--model``, ``hnn.load_run``, both studies, the peers table and
``python analysis/readme.py kinds`` read the same row. A new kind is one model module and one row:

    MODEL_KINDS["toy"] = ModelKind("my_package.toy:ToyModel", lambda cls, spec: cls(spec.input_dim),
                                   doc=KindDoc(line=..., assumes=..., coordinates=..., integrator=..., when=...))

Torch-free on purpose: ``train.py --help`` lists the kinds and their prose before torch loads. A row
names its model class as ``"module:Class"`` (imported on first use: a relative module is read from
``hnn``) or gives the class itself; the class, the builder's model and the objective load on first build.
"""
from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from . import names
from .kind_docs import KindDoc
from .specs import ModelSpec


def _check_ref(ref: str) -> None:
    """A ValueError unless ``ref`` reads ``"module:name"`` (checked when a row is written, torch-free)."""
    module, _, name = ref.partition(":")
    if not module or not name.isidentifier():
        raise ValueError(f"{ref!r} is not 'module:name' (e.g. '.models.hamiltonian:HNN' or 'my_package.toy:Toy')")


@functools.cache
def _imported(ref: str) -> Any:
    """The object ``"module:name"`` names (a module starting with ``.`` is read from ``hnn``)."""
    module, _, name = ref.partition(":")
    found = getattr(importlib.import_module(module, __package__), name, None)
    if found is None:
        raise ImportError(f"{ref!r}: module {module} has no {name}; a row of hnn.MODEL_KINDS names its class "
                          "'module:Class'")
    return found


def _resolved(ref) -> Any:
    return _imported(ref) if isinstance(ref, str) else ref


def _checked_model(cls) -> type:
    from .interface import Model      # a class is given or imported: torch is loaded already
    if not (isinstance(cls, type) and issubclass(cls, Model)):
        raise TypeError(f"ModelKind.model must be an hnn.Model subclass, got {cls!r}")
    return cls


def _plain(cls, spec: ModelSpec):
    """The default builder: ``cls(input_dim, hidden_dim, nonlinearity)`` (the structured kinds)."""
    return cls(spec.input_dim, spec.hidden_dim, spec.nonlinearity)


@dataclass(frozen=True)
class ModelKind:
    """A model kind: ``source``, its model class or ``"module:Class"`` (``model``: the class, whose
    declarations the studies read); ``builder(cls, spec)``, its untrained model from the class and a
    run's ``ModelSpec`` (also rebuilds it on load; default ``cls(input_dim, hidden_dim, nonlinearity)``);
    ``objective``, the class (or ``"module:Class"``) that trains it by default; its plot ``color``;
    ``studied``: whether the studies (scene, measured, peers) train it by default (False for a kind
    whose rollouts are not yet affordable there); ``doc``, its prose for readers (``--help``, the
    README, docs/python.md); ``family``: None for a kind any task's ``--model`` may take, or the family
    whose tasks alone take it (``'pixel'``: its name is ``pixel-<model>``, and the pixel task's
    ``KIND_PREFIX`` adds it); ``grouping``: how a sweep trains its seeds as one program
    (``hnn.names.GROUPINGS``: ``'closed_form'``, the hand-written gradients of ``hnn.trainers.closed_form``;
    ``'vmap'``, any kind under ``torch.vmap`` over stacked weights, ``hnn.trainers.vmap``, whose contract
    ``hnn.Model`` states; ``'alone'``, one at a time). Only ``model``, ``build`` and ``make_objective``
    import anything."""
    source: type | str
    builder: Callable[[type, ModelSpec], Any] | None = None
    objective: type | str = ".objectives:DerivativeObjective"
    color: str = "tab:gray"
    studied: bool = True
    doc: KindDoc | None = None
    family: str | None = None
    grouping: str = "vmap"

    def __post_init__(self):
        if self.grouping not in names.GROUPINGS:
            raise ValueError(f"ModelKind.grouping={self.grouping!r}: choose one of {', '.join(names.GROUPINGS)}")
        for ref in (self.source, self.objective):
            if isinstance(ref, str):
                _check_ref(ref)
        if not isinstance(self.source, str):
            _checked_model(self.source)
        if self.doc is not None and not isinstance(self.doc, KindDoc):
            raise TypeError(f"ModelKind.doc must be an hnn.kind_docs.KindDoc, got {self.doc!r}")

    @property
    def model(self) -> type:
        """Its model class (an ``hnn.Model`` subclass), imported on first use."""
        return _checked_model(_resolved(self.source))

    def build(self, spec: ModelSpec):
        """The untrained model of ``spec`` (torch's default dtype; ``model_from_args`` inits and moves it)."""
        return (self.builder or _plain)(self.model, spec)

    def make_objective(self):
        """A new objective of the class that trains this kind by default."""
        return _resolved(self.objective)()

    @property
    def coordinates(self) -> str:
        """The state its field reads (``hnn.interface.COORDINATES``)."""
        return self.model.coordinates

    @property
    def conservative(self) -> bool:
        """It learns an H that its flow conserves (``model.hamiltonian``)."""
        return self.model.conservative

    @property
    def separable(self) -> bool:
        """That H is T(p) + V(q): explicit symplectic solvers apply to the learned model."""
        return self.model.separable

    @property
    def dissipative(self) -> bool:
        """Its flow loses energy on purpose (no energy drift is measured)."""
        return self.model.dissipative

    @property
    def steps(self) -> bool:
        """A learned map: its model steps x -> x(t + dt) itself at its data's step (``hnn.models.maps``), no field."""
        return self.model.steps

    def reads(self, observed: str) -> bool:
        """Whether its model can be fit to states in ``observed`` coordinates (as they are, or mapped)."""
        model = self.model
        return observed == model.coordinates or observed in model.takes or observed in model.maps


def _hnn(cls, spec: ModelSpec):
    from .models.hamiltonian import build_model
    return build_model(spec.input_dim, spec.hidden_dim, spec.nonlinearity, False, spec.field_type)


def _baseline(cls, spec: ModelSpec):
    from .models.hamiltonian import build_model
    return build_model(spec.input_dim, spec.hidden_dim, spec.nonlinearity, True, spec.field_type)


def _width_map(cls, spec: ModelSpec):
    """A learned map of ``map_layers`` layers of ``hidden_dim`` terms each, at the data's step ``dt``."""
    return cls(spec.input_dim, spec.hidden_dim, spec.map_layers, spec.nonlinearity, dt=spec.dt)


def _la_map(cls, spec: ModelSpec):
    """An LA-SympNet has no width: ``map_layers`` linear modules of 2 shears each (jpzxshi/sympnets' pendulum)."""
    return cls(spec.input_dim, spec.map_layers, 2, spec.nonlinearity, dt=spec.dt)


def _pixel(cls, spec: ModelSpec):
    return cls(spec.input_dim, spec.latent_dim, spec.hidden_dim, spec.nonlinearity,
               field_type=spec.field_type, autoencoder_nonlinearity=spec.ae_nonlinearity)


def _second_order(cls, spec: ModelSpec):
    return cls(spec.input_dim, spec.hidden_dim, spec.nonlinearity, periodic=spec.periodic)


def _lagrangian(cls, spec: ModelSpec):
    return cls(spec.input_dim, spec.hidden_dim, spec.nonlinearity, periodic=spec.periodic, solve=spec.lnn_solve)


def _constrained(cls, spec: ModelSpec):
    from .models.constrained import ConstraintGraph
    if spec.constraints is None:
        raise ValueError(f"the {spec.kind} kind needs the task's constraint graph (ModelSpec.constraints, "
                         "from its config's model_facts()); this task declares none: train it on the chain task "
                         "(experiment-chain) or give the task's Config a model_facts() with 'constraints'")
    return cls(ConstraintGraph.from_dict(spec.constraints), spec.hidden_dim, spec.nonlinearity)


def _pair(cls, spec: ModelSpec):
    if spec.bodies is None:
        raise ValueError(f"the {spec.kind} kind reads the state as bodies and needs the task's layout (ModelSpec.bodies, "
                         "from its config's model_facts()); this task declares none: train it on a task of bodies "
                         "(2body, 3body, lattice) or give the task's Config a BODIES = hnn.bodies.Bodies(...)")
    return cls(spec.bodies, spec.hidden_dim, spec.nonlinearity)


_PIXEL_OBJECTIVE = ".objectives:PixelObjective"

# the one place a kind is named and described; a run's config says which (RunConfig.kind), its args.json too
MODEL_KINDS: dict[str, ModelKind] = {
    "hnn": ModelKind(".models.hamiltonian:HNN", _hnn, color="tab:blue", grouping="closed_form", doc=KindDoc(
        line="the paper's HNN: one MLP learns H(q, p), and dx/dt is its symplectic gradient",
        assumes="a conserved energy H(q, p) and nothing about its form",
        coordinates="canonical x = [q, p]. On measured [q, qdot] it takes qdot as p, which is right when "
                    "p is a constant multiple of qdot (one body of constant mass: the real pendulum) and wrong "
                    "when the mass depends on q (a pendulum chain): use `mechanical` there",
        integrator="`midpoint` for long rollouts (symplectic for any H: the learned energy stays bounded); "
                   "`dop853`, `dopri5` or `rk4` for short accurate paths",
        when="a closed system without friction, in canonical coordinates; the paper's tasks")),
    "baseline": ModelKind(".models.hamiltonian:Baseline", _baseline, color="tab:red", grouping="closed_form",
                          doc=KindDoc(
        line="an MLP that predicts dx/dt directly (the paper's baseline; also `--baseline`)",
        assumes="nothing: any smooth field x -> dx/dt",
        coordinates="any state; it reads no structure into the columns",
        integrator="`rk4`, `dopri5` or `dop853` (it has no structure to keep)",
        when="a reference to measure a structured kind against, or a system with forcing where no energy "
             "exists; its energy drifts on long rollouts")),
    "separable": ModelKind(".models.structured:SeparableHNN", color="tab:green", grouping="closed_form", doc=KindDoc(
        line="H = T(p) + V(q), two MLPs; explicit leapfrog is exactly symplectic for it",
        assumes="a conserved energy whose kinetic part does not depend on q (particles of constant mass "
                "in Cartesian coordinates)",
        coordinates="canonical x = [q, p]",
        integrator="`leapfrog` or `yoshida4`: explicit, symplectic for the learned H, one dT/dp and one dV/dq "
                   "a step",
        when="long rollouts of particle systems (springs, orbits); not for systems whose mass depends on q")),
    "dissipative": ModelKind(".models.structured:DissipativeHNN", color="tab:purple", grouping="closed_form",
                             doc=KindDoc(
        line="dx/dt = J grad H + grad D (the D-HNN): a conserved H and a dissipative potential D learned together",
        assumes="energy lost (or gained) along a gradient field; J grad H + grad D can represent any smooth "
                "planar field (Helmholtz), so it constrains the fit no more than the baseline does",
        coordinates="canonical x = [q, p]",
        integrator="`rk4`, `dopri5` or `dop853`: its flow is not symplectic on purpose",
        when="friction you can see in the data and accurate dx/dt targets (central differences, as the "
             "D-HNN paper's `--split dhnn`); on the real pendulum's forward differences it fits the noise as "
             "the baseline does and rolls out as badly (docs/scenes.md)")),
    "mechanical": ModelKind(".models.mechanical:MechanicalHNN", _second_order, color="tab:olive", doc=KindDoc(
        line="H = 1/2 p^T M^-1(q) p + V(q) with a learned positive definite mass matrix",
        assumes="a conserved energy, kinetic energy quadratic in the momenta (any mechanical system: "
                "pendulums, chains, springs)",
        coordinates="canonical [q, p]; on measured [q, qdot] (a dataset whose `state` is `velocity`, as the "
                    "chain task's) it maps qdot to p = M(q) qdot itself, so it is the HNN for observed "
                    "velocities. `periodic=True` when q are angles",
        integrator="`midpoint` (symplectic for any H), `dopri5` or `rk4`; not `leapfrog` or `yoshida4` (its H is "
                   "not separable)",
        when="mechanical systems, above all measured positions and velocities (the README's model guide "
             "picks it for the spring, pendulum and real pendulum)")),
    "second_order": ModelKind(".models.mechanical:SecondOrderNODE", _second_order, color="tab:orange", doc=KindDoc(
        line="dq/dt = v, dv/dt = f(q, v): the baseline with second-order structure and no energy",
        assumes="the state is positions and their velocities; nothing about energy",
        coordinates="observed [q, qdot] only (the objectives refuse it on canonical [q, p])",
        integrator="`rk4` or `dopri5`",
        when="a structured baseline for mechanical systems with friction or forcing, beside `mechanical`")),
    "constrained": ModelKind(".models.constrained:ConstrainedHNN", _constrained, color="tab:cyan", doc=KindDoc(
        line="CHNN (Finzi et al. 2020): point masses in Cartesian [x, p], a learned potential V(x) and one mass "
             "per body, the task's rigid links and tethers enforced by projection",
        assumes="bodies of constant mass joined by known rigid constraints (a chain, a linkage), a conserved "
                "energy 1/2 sum |p_i|^2 / m_i + V(x)",
        coordinates="Cartesian positions of the bodies and their momenta; it maps observed [x, xdot] through its "
                    "masses. The task gives the constraint graph (the chain task converts its angles)",
        integrator="`dopri5` or `rk4` (the projection keeps the constraints; its H is not separable)",
        when="linkages and chains whose constraints you know: it models what the scene is, and beats the "
             "generalized-coordinate kinds on chains (docs/peers.md)")),
    "constrained_lagrangian": ModelKind(".models.constrained:ConstrainedLNN", _constrained, color="tab:pink",
                                        doc=KindDoc(
        line="CLNN (Finzi et al. 2020): the constrained kind in Lagrangian form, Cartesian [x, xdot], the "
             "constraint forces solved for",
        assumes="as `constrained`: bodies of constant mass, known rigid constraints, a potential V(x)",
        coordinates="Cartesian positions of the bodies and their velocities, as observed",
        integrator="`dopri5` or `rk4`",
        when="as `constrained`, when you would rather not map velocities to momenta; the same cost per step "
             "or less")),
    # not in the scene studies: a barely trained black-box L's flow is stiff (one dopri5 rollout of it took
    # minutes in the measured study); the peers' tables train it with the LNN's own activation and give its
    # rollouts an iteration budget (analysis/chains/peers.py)
    "lagrangian": ModelKind(".models.lagrangian:LagrangianNN", _lagrangian, color="tab:brown", studied=False,
                            doc=KindDoc(
        line="LNN (Cranmer et al. 2020): a black-box L(q, qdot) MLP; qddot from the Euler-Lagrange equations",
        assumes="a conserved energy E = qdot . dL/dqdot - L and a Lagrangian whose Hessian in qdot is invertible "
                "(a singular one is an error naming the state; `--lnn_solve pinv` takes the LNN authors' "
                "pseudo-inverse there instead, as the peers' table does)",
        coordinates="observed [q, qdot] only",
        integrator="`dopri5` or `rk4`; not `discrete_gradient` (its flow is not S grad E in [q, qdot])",
        when="observed positions and velocities when you want an energy but not a Hamiltonian's momenta; each "
             "field call solves an n x n system per state, so it is the costliest kind per step")),
    "g_sympnet": ModelKind(".models.maps:GSympNet", _width_map, ".objectives.map:MapObjective", color="tab:gray",
                           doc=KindDoc(
        line="G-SympNet (Jin et al. 2020): a learned symplectic map x_k -> x_{k+1}, one pass a step, no integrator",
        assumes="the data's flow over one step is a symplectic map (a Hamiltonian system without friction), "
                "and the data are paths at a fixed step dt; it learns gradient shears p <- p + grad V(q), "
                "q <- q + grad T(p)",
        coordinates="canonical x = [q, p] only: a map symplectic in [q, qdot] is wrong where the mass depends on "
                    "q, so the chain's and measured files' velocities are refused",
        integrator="none: `hnn.rollout(model, x0, t_eval)` steps the map itself, on t_eval of multiples of its "
                   "dt (another step is an error naming it)",
        when="the cheapest rollout of a conservative system sampled at one step: one pass of "
             "`--map_layers` shears a step where RK4 calls a learned field four times (docs/maps.md)")),
    # the scene studies measure one map kind, g_sympnet, whose width their grid varies (an LA-SympNet has none);
    # docs/maps.md (analysis/benchmarks/maps.py) sets the three side by side on the SympNets protocols
    "la_sympnet": ModelKind(".models.maps:LASympNet", _la_map, ".objectives.map:MapObjective", color="silver",
                            studied=False, doc=KindDoc(
        line="LA-SympNet (Jin et al. 2020): a symplectic map of linear and activation shears",
        assumes="as `g_sympnet`: a symplectic one-step map, paths at a fixed step",
        coordinates="canonical x = [q, p] only",
        integrator="none: `hnn.rollout` steps the map itself at its dt",
        when="few degrees of freedom and few parameters (`--hidden_dim` is not read; `--map_layers` linear "
             "modules of 2 shears each)")),
    "henon": ModelKind(".models.maps:HenonNet", _width_map, ".objectives.map:MapObjective", color="darkgray",
                       studied=False, doc=KindDoc(
        line="HenonNet (Burby et al. 2020): a symplectic map of Henon layers",
        assumes="as `g_sympnet`: a symplectic one-step map, paths at a fixed step; each layer is four times "
                "(q, p) -> (p + eta, -q + grad V(p))",
        coordinates="canonical x = [q, p] only",
        integrator="none: `hnn.rollout` steps the map itself at its dt",
        when="as `g_sympnet`; four potential gradients a layer, so a step costs about four G-SympNet layers")),
    # the pair sum's autograd in r runs one model at a time (no group program written for it yet); the studies
    # train it where a task declares its bodies (2body, 3body): its builder refuses a task that declares none
    "pairwise": ModelKind(".models.pair:PairHNN", _pair, color="darkgoldenrod", grouping="alone",
                          doc=KindDoc(
        line="H = sum |p_i|^2 / (2 m_i) + sum over pairs V(|q_i - q_j|): one learned function of one distance "
             "for every pair, and a mass per species",
        assumes="bodies that interact in pairs through their distance alone (gravity, springs, Lennard-Jones), "
                "identical bodies exchangeable, no preferred origin or direction (an optional one-body field "
                "U(q_i) where the task declares one); invariant under translation, rotation and permutation by "
                "construction, and one set of weights reads any number of bodies",
        coordinates="canonical x = [q, p] of the bodies the task declares (hnn.bodies.Bodies: count, dimension, "
                    "order); it reads a state of any N in that layout",
        integrator="`leapfrog` or `yoshida4` (its H is T(p) + V(q)); `dopri5` for short accurate paths",
        when="scenes of many bodies: fit on a few, roll out on many (docs/bodies.md); by Adam at `--hidden_dim "
             "64`, as the studies train it (V reads one distance: the 2-body and 3-body tasks' width of 200 "
             "trained it hundreds of times worse on the 3-body, docs/bodies.md); `--fit library` prints V as an equation of r, "
             "`--fit swim` or `elm` fits sampled radial neurons")),
    # the pixel objective draws its own noise per model: the seeds train one at a time
    "pixel-hnn": ModelKind(".models.pixel:PixelHNN", _pixel, _PIXEL_OBJECTIVE, color="tab:blue", family="pixel",
                           grouping="alone", doc=KindDoc(
        line="the pixel task's HNN: an autoencoder of frames and an HNN on its 2-D latent "
             "(`experiment-pixels/train.py --model hnn`)",
        assumes="the frames come from a system with a conserved energy in a 2-D latent",
        coordinates="a learned latent [q, p]; the inputs are pairs of frames",
        integrator="in the latent: `midpoint` for long rollouts, `rk4` for short ones",
        when="a system seen only as pictures")),
    "pixel-baseline": ModelKind(".models.pixel:PixelBaseline", _pixel, _PIXEL_OBJECTIVE, color="tab:red",
                                family="pixel", grouping="alone", doc=KindDoc(
        line="the pixel task's baseline: the same autoencoder, an MLP predicting the latent's derivative "
             "(`experiment-pixels/train.py --model baseline`)",
        assumes="nothing about the latent's dynamics",
        coordinates="a learned 2-D latent",
        integrator="`rk4` in the latent",
        when="the reference for `pixel-hnn`")),
}




def _check_names(kinds: dict) -> None:
    """A kind's name holds a hyphen exactly where it has a family, and starts with it: ``pixel-hnn``."""
    for name, row in kinds.items():
        if ("-" in name) != (row.family is not None) or (row.family and not name.startswith(row.family + "-")):
            raise ImportError(f"model kind {name!r}: a name with a hyphen is '<family>-<model>' of a row declaring "
                              f"that family (family={row.family!r})")


_check_names(MODEL_KINDS)


# RunConfig.objective's choices: each name of hnn.names' list the class that fits it ("module:Class",
# imported on first read, as a kind's ``source``)
_OBJECTIVE_CLASSES = names.checked({"derivative": ".objectives:DerivativeObjective",
                                    "trajectory": ".objectives.trajectory:TrajectoryObjective",
                                    "discrete_gradient": ".objectives.dgnet:DiscreteGradientObjective",
                                    "map": ".objectives.map:MapObjective"}, names.OBJECTIVES, "hnn.kinds._OBJECTIVE_CLASSES")


class _Objectives(Mapping):
    """``RunConfig.objective``'s choices, name -> class (``_OBJECTIVE_CLASSES``, imported on first read)."""

    def __getitem__(self, name: str) -> type:
        return _resolved(_OBJECTIVE_CLASSES[name])

    def __iter__(self) -> Iterator[str]:
        return iter(_OBJECTIVE_CLASSES)

    def __len__(self) -> int:
        return len(_OBJECTIVE_CLASSES)

    def __repr__(self) -> str:
        return f"OBJECTIVES({', '.join(_OBJECTIVE_CLASSES)})"


OBJECTIVES: Mapping[str, type] = _Objectives()


def get_kind(kind: str) -> ModelKind:
    """The row of ``kind``, or a ValueError naming the known kinds."""
    if kind not in MODEL_KINDS:
        raise ValueError(f"unknown model kind {kind!r}; known: {sorted(MODEL_KINDS)}")
    return MODEL_KINDS[kind]


def get_objective(name: str, **options):
    """A new objective called ``name`` (a key of ``OBJECTIVES``), built with ``options``."""
    if name not in OBJECTIVES:
        raise ValueError(f"unknown objective {name!r}; choose one of {sorted(OBJECTIVES)}")
    return OBJECTIVES[name](**options)


def objective_for(kind: str):
    """An objective that trains models of ``kind`` by default (its arrays are the defaults)."""
    return get_kind(kind).make_objective()


DTYPES = names.DTYPES       # a run's dtype: the name of a torch dtype


def model_from_args(args: dict, device="cpu"):
    """The untrained model that a run with these (saved) args trains, of the ``kind`` it recorded
    (float32 unless its ``dtype`` says otherwise): ``model_from_spec`` of its ``ModelSpec``, answering in
    the user's units where the args record a run's ``unit_scales`` (``--units``: ``hnn.units.Rescaled``)."""
    model = model_from_spec(ModelSpec.from_args(args), device)
    if args.get("unit_scales") is None:
        return model
    from .units import wrap_saved       # its scale buffers follow the inner model's dtype and device
    return wrap_saved(model, args)


def model_from_spec(spec: ModelSpec, device="cpu"):
    """The untrained model of ``spec`` (``hnn.specs.run_specs(config).model``), built by its kind's row,
    initialized by ``spec.init`` and put on ``spec.dtype`` and ``device``; for a least-squares fit
    (``spec.fit`` other than ``'adam'``) the fit's own model (``hnn.fits.build``), float64 on the CPU, where
    its solve runs whatever ``device`` says (``hnn.load_run(folder, device)`` moves it after).

    The weights are drawn on the CPU whatever torch's default device, then moved: one seed gives the
    same initial model on every device (a GPU's generator draws other numbers)."""
    import torch
    from .models.mlp import initialize
    if spec.dtype not in DTYPES:
        raise ValueError(f"dtype={spec.dtype!r}: choose one of {', '.join(DTYPES)}")
    if spec.fit != "adam":      # a least-squares fit's own model, float64 on the CPU where its QR runs (hnn.fits)
        from .fits.registry import build
        with torch.device("cpu"):
            return build(spec)
    with torch.device("cpu"):
        model = initialize(get_kind(spec.kind).build(spec), spec.init)
    return model.to(dtype=getattr(torch, spec.dtype), device=device)


def described() -> list[tuple[str, KindDoc | None]]:
    """``(kind, its prose or None)`` of every registered kind, in the registry's order (the pages' lists)."""
    return [(kind, row.doc) for kind, row in MODEL_KINDS.items()]
