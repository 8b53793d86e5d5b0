"""The compute a process uses: the cores it may run on (``cores``) and torch's thread count for a block
of work (``torch_threads``), the caller's count back afterwards however the block ends.

    with torch_threads(1):          # a rollout of a few states: a second thread only adds contention
        path = hnn.rollout(model, x0, t_eval)

Why one thread so often: docs/speed.md#threads (two torch processes of 2 threads each on a 2-core box
ran many times slower than one).
"""
from __future__ import annotations

import contextlib
import os


def cores() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


@contextlib.contextmanager
def torch_threads(count: int | None):
    """Torch's thread count at ``count`` inside the block (None: left as it is); the caller's count is
    restored on the way out, however the block ends."""
    import torch        # here: a command's parser runs before torch is imported (hnn.command)

    caller = torch.get_num_threads()
    if count is not None and count < 1:
        raise ValueError(f"torch_threads({count}): a thread count is at least 1 (or None to leave it)")
    if count is not None and count != caller:      # setting it costs a call into the thread pool: only if it moves
        torch.set_num_threads(count)
    try:
        yield
    finally:
        if torch.get_num_threads() != caller:
            torch.set_num_threads(caller)
