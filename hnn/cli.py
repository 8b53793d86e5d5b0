"""One argument parser for every ``train.py``: the original's flags, declared once.

Each task passes its own defaults (the original hard-coded some of them, such as the weight
decay; here every knob is a flag with the original's value as its default).
"""
from __future__ import annotations

import argparse


def _optional_int(text: str):
    return None if text.lower() in ("none", "0", "full") else int(text)


def make_parser(description: str, *, name: str, input_dim: int, save_dir: str, weight_decay: float,
                total_steps: int = 2000, batch_size: int | None = None, learn_rate: float = 1e-3,
                hidden_dim: int = 200, rk4_help: str | None = None) -> argparse.ArgumentParser:
    """The shared flags with one task's defaults; a task may add flags of its own."""
    p = argparse.ArgumentParser(description=description,
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--input_dim", type=int, default=input_dim, help="width of the state x = [q, p]")
    p.add_argument("--hidden_dim", type=int, default=hidden_dim, help="hidden units per layer of the MLP")
    p.add_argument("--learn_rate", type=float, default=learn_rate, help="Adam learning rate")
    p.add_argument("--weight_decay", type=float, default=weight_decay,
                   help="Adam weight decay (hard-coded per task in the original)")
    p.add_argument("--batch_size", type=_optional_int, default=batch_size,
                   help="minibatch size; none/0 = full batch")
    p.add_argument("--nonlinearity", type=str, default="tanh",
                   help="tanh, relu, sigmoid, softplus, selu, elu or swish")
    p.add_argument("--total_steps", type=int, default=total_steps,
                   help="optimizer steps; the loop runs total_steps + 1, as the original")
    p.add_argument("--print_every", type=int, default=200, help="print (and test) every N steps")
    p.add_argument("--name", type=str, default=name, help="run name, the prefix of the run folder")
    p.add_argument("--baseline", action="store_true", help="train the baseline (an MLP predicting dx/dt directly)")
    p.add_argument("--use_rk4", action="store_true", help=rk4_help or (
        "fit the RK4 average slope of the learned field over one data time step dt, (x(t+dt) - x(t))/dt "
        "of one RK4 step, to the true dx/dt (the original crashed on this flag); default: fit dx/dt itself"))
    p.add_argument("--verbose", action="store_true", help="print the loss every print_every steps")
    p.add_argument("--field_type", type=str, default="solenoidal",
                   help="solenoidal (Hamiltonian), conservative, or both")
    p.add_argument("--seed", type=int, default=0, help="seeds the dataset, the init and the minibatches")
    p.add_argument("--save_dir", type=str, default=save_dir,
                   help="folder that receives the run folder <name>-<hnn|baseline>-seed<seed>/")
    p.add_argument("--device", type=str, default="cpu", help="torch device, e.g. cpu or cuda")
    p.add_argument("--dtype", type=str, default="float32", choices=("float32", "float64"),
                   help="dtype of the model and the data")
    return p
