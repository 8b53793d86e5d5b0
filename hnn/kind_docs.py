"""What each model kind is, in words: the one place the README's model list, docs/python.md's
paragraphs and ``--model``'s help read it from (``python analysis/readme.py kinds`` writes both
pages; ``tests/test_kind_docs.py`` checks that every kind registered in ``hnn.MODEL_KINDS`` has an
entry here and appears on both pages).

Torch-free on purpose: ``train.py --help`` lists the kinds before torch loads. A kind added
at run time (a row of ``hnn.MODEL_KINDS``) without an entry here still trains; ``--model`` offers it
once its module is imported.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class KindDoc:
    """A model kind, for a reader: ``line`` (the README's one line and ``--model``'s help), what it
    ``assumes``, its ``coordinates``, the ``integrator`` to roll it out with, and ``when`` to use it."""
    line: str
    assumes: str
    coordinates: str
    integrator: str
    when: str


KIND_DOCS = {
    "hnn": KindDoc(
        line="the paper's HNN: one MLP learns H(q, p), and dx/dt is its symplectic gradient",
        assumes="a conserved energy H(q, p) and nothing about its form",
        coordinates="canonical x = [q, p]. On measured [q, qdot] it takes qdot as p, which is right when "
                    "p is a constant multiple of qdot (one body of constant mass: the real pendulum) and wrong "
                    "when the mass depends on q (a pendulum chain): use `mechanical` there",
        integrator="`midpoint` for long rollouts (symplectic for any H: the learned energy stays bounded); "
                   "`dop853`, `dopri5` or `rk4` for short accurate paths",
        when="a closed system without friction, in canonical coordinates; the paper's tasks"),
    "baseline": KindDoc(
        line="an MLP that predicts dx/dt directly (the paper's baseline; also `--baseline`)",
        assumes="nothing: any smooth field x -> dx/dt",
        coordinates="any state; it reads no structure into the columns",
        integrator="`rk4`, `dopri5` or `dop853` (it has no structure to keep)",
        when="a reference to measure a structured kind against, or a system with forcing where no energy "
             "exists; its energy drifts on long rollouts"),
    "separable": KindDoc(
        line="H = T(p) + V(q), two MLPs; explicit leapfrog is exactly symplectic for it",
        assumes="a conserved energy whose kinetic part does not depend on q (particles of constant mass "
                "in Cartesian coordinates)",
        coordinates="canonical x = [q, p]",
        integrator="`leapfrog` or `yoshida4`: explicit, symplectic for the learned H, one dT/dp and one dV/dq "
                   "a step",
        when="long rollouts of particle systems (springs, orbits); not for systems whose mass depends on q"),
    "dissipative": KindDoc(
        line="dx/dt = J grad H + grad D (the D-HNN): a conserved H and a dissipative potential D learned together",
        assumes="energy lost (or gained) along a gradient field; J grad H + grad D can represent any smooth "
                "planar field (Helmholtz), so it constrains the fit no more than the baseline does",
        coordinates="canonical x = [q, p]",
        integrator="`rk4`, `dopri5` or `dop853`: its flow is not symplectic on purpose",
        when="friction you can see in the data and accurate dx/dt targets (central differences, as the "
             "D-HNN paper's `--split dhnn`); on the real pendulum's forward differences it fits the noise as "
             "the baseline does and rolls out as badly (docs/scenes.md)"),
    "mechanical": KindDoc(
        line="H = 1/2 p^T M^-1(q) p + V(q) with a learned positive definite mass matrix",
        assumes="a conserved energy, kinetic energy quadratic in the momenta (any mechanical system: "
                "pendulums, chains, springs)",
        coordinates="canonical [q, p]; on measured [q, qdot] (a dataset whose `state` is `velocity`, as the "
                    "chain task's) it maps qdot to p = M(q) qdot itself, so it is the HNN for observed "
                    "velocities. `periodic=True` when q are angles",
        integrator="`midpoint` (symplectic for any H), `dopri5` or `rk4`; not `leapfrog` or `yoshida4` (its H is "
                   "not separable)",
        when="mechanical systems, above all measured positions and velocities (the README's model guide "
             "picks it for the spring, pendulum and real pendulum)"),
    "second_order": KindDoc(
        line="dq/dt = v, dv/dt = f(q, v): the baseline with second-order structure and no energy",
        assumes="the state is positions and their velocities; nothing about energy",
        coordinates="observed [q, qdot] only (the objectives refuse it on canonical [q, p])",
        integrator="`rk4` or `dopri5`",
        when="a structured baseline for mechanical systems with friction or forcing, beside `mechanical`"),
    "constrained": KindDoc(
        line="CHNN (Finzi et al. 2020): point masses in Cartesian [x, p], a learned potential V(x) and one mass "
             "per body, the task's rigid links and tethers enforced by projection",
        assumes="bodies of constant mass joined by known rigid constraints (a chain, a linkage), a conserved "
                "energy 1/2 sum |p_i|^2 / m_i + V(x)",
        coordinates="Cartesian positions of the bodies and their momenta; it maps observed [x, xdot] through its "
                    "masses. The task gives the constraint graph (the chain task converts its angles)",
        integrator="`dopri5` or `rk4` (the projection keeps the constraints; its H is not separable)",
        when="linkages and chains whose constraints you know: it models what the scene is, and beats the "
             "generalized-coordinate kinds on chains (docs/peers.md)"),
    "constrained_lagrangian": KindDoc(
        line="CLNN (Finzi et al. 2020): the constrained kind in Lagrangian form, Cartesian [x, xdot], the "
             "constraint forces solved for",
        assumes="as `constrained`: bodies of constant mass, known rigid constraints, a potential V(x)",
        coordinates="Cartesian positions of the bodies and their velocities, as observed",
        integrator="`dopri5` or `rk4`",
        when="as `constrained`, when you would rather not map velocities to momenta; the same cost per step "
             "or less"),
    "lagrangian": KindDoc(
        line="LNN (Cranmer et al. 2020): a black-box L(q, qdot) MLP; qddot from the Euler-Lagrange equations",
        assumes="a conserved energy E = qdot . dL/dqdot - L and a Lagrangian whose Hessian in qdot is invertible "
                "(a singular one is an error naming the state)",
        coordinates="observed [q, qdot] only",
        integrator="`dopri5` or `rk4`; not `discrete_gradient` (its flow is not S grad E in [q, qdot])",
        when="observed positions and velocities when you want an energy but not a Hamiltonian's momenta; each "
             "field call solves an n x n system per state, so it is the costliest kind per step"),
    "pixel-hnn": KindDoc(
        line="the pixel task's HNN: an autoencoder of frames and an HNN on its 2-D latent "
             "(`experiment-pixels/train.py --model hnn`)",
        assumes="the frames come from a system with a conserved energy in a 2-D latent",
        coordinates="a learned latent [q, p]; the inputs are pairs of frames",
        integrator="in the latent: `midpoint` for long rollouts, `rk4` for short ones",
        when="a system seen only as pictures"),
    "pixel-baseline": KindDoc(
        line="the pixel task's baseline: the same autoencoder, an MLP predicting the latent's derivative "
             "(`experiment-pixels/train.py --model baseline`)",
        assumes="nothing about the latent's dynamics",
        coordinates="a learned 2-D latent",
        integrator="`rk4` in the latent",
        when="the reference for `pixel-hnn`"),
}


def model_help(names, prefix: str = "") -> str:
    """``--model``'s help: each of ``names`` with the one line of kind ``prefix + name`` (a kind
    without an entry: its name alone)."""
    docs = [KIND_DOCS.get(prefix + name) for name in names]
    return "model kind: " + "; ".join(f"{name} ({doc.line})" if doc else name for name, doc in zip(names, docs))


def readme_lines(kinds) -> str:
    """The README's list: one line per kind."""
    return "\n".join(f"- `{kind}`: {KIND_DOCS[kind].line}." for kind in kinds)


def python_paragraphs(kinds) -> str:
    """docs/python.md's section: a paragraph per kind."""
    return "\n\n".join(f"**`{kind}`**: {doc.line}. *Assumes* {doc.assumes}. *Coordinates*: {doc.coordinates}. "
                       f"*Roll it out with* {doc.integrator}. *Use it for* {doc.when}."
                       for kind, doc in ((kind, KIND_DOCS[kind]) for kind in kinds))
