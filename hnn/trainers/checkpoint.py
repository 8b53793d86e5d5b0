"""A training checkpoint: a loop's state (weights, optimizer, samplers, stats so far) saved now and then
to one file, atomically, and read back, so that a killed run resumes where it stopped, to the same floats
(the lone loop's, ``hnn.trainers.loop``, and a group's, ``hnn.trainers.group_loop.GroupCheckpoint``)."""
from __future__ import annotations

from pathlib import Path

import torch

from ..io import atomic_write, torch_bytes

# seconds of training between two checkpoints of a run that keeps one (``train(checkpoint=...)``): a
# killed run loses at most this much; saving a 256-wide model and its Adam moments takes milliseconds
CHECKPOINT_EVERY = 60.0
_CHECKPOINT_FORMAT = 1


def save_checkpoint(path: Path, step: int, total_steps: int, model, optim, gens, stats: dict, seconds: float):
    """Write a training loop's state after ``step`` to ``path``, atomically: ``model``'s and ``optim``'s
    ``state_dict``, the samplers ``gens`` (``torch.Generator``), the ``stats`` so far (tensors, lists and
    numbers) and the seconds trained (every loop of ``hnn.trainers``)."""
    state = {"format": _CHECKPOINT_FORMAT, "step": step, "total_steps": total_steps, "seconds": seconds,
             "model": model.state_dict(), "optim": optim.state_dict(), "gens": [g.get_state() for g in gens],
             "stats": stats}
    atomic_write(path, lambda tmp: Path(tmp).write_bytes(torch_bytes(state)))


def load_checkpoint(path: Path, model, optim, gens, total_steps: int) -> tuple[int, dict, float]:
    """Load a ``save_checkpoint`` into the model, optimizer and samplers: ``(the first step still to run, the stats
    so far, the seconds trained so far)``."""
    fix = f"delete {path} to train from the start"
    try:
        state = torch.load(path, map_location=next(model.parameters()).device, weights_only=True)
    except Exception as err:
        first_line = (str(err).splitlines() or [""])[0]
        raise ValueError(f"the training checkpoint {path} cannot be read ({type(err).__name__}: {first_line}); "
                         f"{fix}") from err
    if not isinstance(state, dict) or state.get("format") != _CHECKPOINT_FORMAT:
        raise ValueError(f"{path} is not a training checkpoint of this version of hnn; {fix}")
    if state["total_steps"] != total_steps:
        raise ValueError(f"the training checkpoint {path} is of a run of {state['total_steps']} steps, "
                         f"not {total_steps}; {fix}")
    try:
        model.load_state_dict(state["model"])
        optim.load_state_dict(state["optim"])
    except (RuntimeError, ValueError, KeyError) as err:
        raise ValueError(f"the training checkpoint {path} is of another model ({err}); {fix}") from err
    if len(state["gens"]) != len(gens):
        raise ValueError(f"the training checkpoint {path} saved {len(state['gens'])} samplers, this run draws from "
                         f"{len(gens)}; {fix}")
    for gen, saved in zip(gens, state["gens"]):
        gen.set_state(saved.cpu())      # the samplers draw on the CPU whatever the model's device
    return state["step"] + 1, state["stats"], state["seconds"]
