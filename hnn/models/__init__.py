"""Models: networks and the fields they make. ``mlp`` and its closed-form kernels (``tanh_mlp``),
the paper's HNN and baseline (``hamiltonian``), the pixel autoencoder (``pixel``), the structured
kinds (``structured``: separable, dissipative; ``mechanical``: M^-1 and V, the second-order NODE;
``constrained``: CHNN and CLNN on a ``ConstraintGraph``; ``lagrangian``: the LNN; ``maps``: learned
symplectic maps, G- and LA-SympNets and HenonNets, which step themselves; ``pair``: the pair kind of bodies,
and ``pair_table``, its fitted V as a table for rollouts). They know no
solver and no objective: each declares what it can do through ``hnn.interface``."""
from .constrained import ConstrainedHNN, ConstrainedLNN, ConstraintGraph
from .hamiltonian import FIELD_TYPES, HNN, Baseline, build_model, permutation_tensor
from .lagrangian import LagrangianNN, SingularLagrangianError
from .maps import GSympNet, HenonNet, LASympNet, SymplecticMap
from .mechanical import MechanicalHNN, SecondOrderNODE
from .mlp import INITS, MLP, NONLINEARITIES, get_nonlinearity, initialize
from .pixel import MLPAutoencoder, PixelBaseline, PixelHNN
from .structured import DissipativeHNN, SeparableHNN

__all__ = ["FIELD_TYPES", "HNN", "INITS", "MLP", "NONLINEARITIES", "Baseline", "ConstrainedHNN", "ConstrainedLNN",
           "ConstraintGraph", "DissipativeHNN", "GSympNet", "HenonNet", "LASympNet", "LagrangianNN", "MLPAutoencoder",
           "MechanicalHNN", "PixelBaseline", "PixelHNN", "SecondOrderNODE", "SeparableHNN", "SingularLagrangianError",
           "SymplecticMap",
           "build_model", "get_nonlinearity", "initialize", "permutation_tensor"]
