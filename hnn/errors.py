"""The errors of a failed rollout, in one module every integrator imports (and nothing else).

``DivergenceError`` names the trajectories and times that blew up; ``ConvergenceError`` (a
subclass) says an implicit step's fixed-point iteration did not converge; ``BudgetError`` (a subclass)
says a rollout was stopped at its budget of field calls before it reached its last time. All are also
``hnn.<name>``.
"""
from __future__ import annotations


class DivergenceError(FloatingPointError):
    """A rollout produced non-finite states. ``trajectories`` and ``times`` say which and when."""

    def __init__(self, message: str, trajectories=(), times=()):
        super().__init__(message)
        self.trajectories = list(trajectories)
        self.times = list(times)


class ConvergenceError(DivergenceError):
    """An implicit step's fixed-point iteration (midpoint, discrete gradient) did not converge;
    ``trajectories``, ``times`` say where.

    A ``DivergenceError``, so code that catches failed rollouts catches this one too.
    """


class BudgetError(DivergenceError):
    """A rollout stopped at its budget of field calls (``calls``) before its last time: a field stiff along
    its path shrinks the step without end, so the rollout is cut off and reported as stopped, not waited
    for (``hnn.evaluation.rollout_budget``). ``why`` says where the budget came from.

    A ``DivergenceError``, so code that catches failed rollouts catches this one too; its outcome reads
    "stopped: over its budget", never a number.
    """

    def __init__(self, message: str, calls: int, why: str = ""):
        super().__init__(message)
        self.calls, self.why = int(calls), why


def divergence_error(message: str, bad_rows, times) -> DivergenceError:
    """The ``DivergenceError`` of a rollout whose rows ``bad_rows`` blew up at ``times`` (same length).

    The message names the first ten as ``#row at t=time`` and how to avoid the blow-up.
    """
    rows = [int(i) for i in bad_rows]
    shown = ", ".join(f"#{i} at t={t:.4g}" for i, t in zip(rows[:10], times[:10]))
    more = f" (+{len(rows) - 10} more)" if len(rows) > 10 else ""
    return DivergenceError(
        f"{message}: {len(rows)} trajectories diverged: {shown}{more}. Reduce the step size or tolerance, "
        "or check that the initial states lie where the model was trained.", rows, list(times))
