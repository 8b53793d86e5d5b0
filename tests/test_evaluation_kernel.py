"""The rollout's evaluation kernel (hnn.models.tanh_mlp.EvaluationKernel): working arrays kept across
calls that leave no trace in the answers, the states it declines, and weights changed between two
rollouts (a training step, ``load_state_dict``) reaching the second."""
import numpy as np
import pytest
import torch

import hnn
from hnn.models.tanh_mlp import KERNEL_MAX_ROWS, EvaluationKernel, mlp_weights

WIDTH = 32
_KINDS = {"hnn": lambda: hnn.build_model(4, WIDTH), "both": lambda: hnn.build_model(4, WIDTH, field_type="both"),
          "baseline": lambda: hnn.build_model(4, WIDTH, baseline=True), "dissipative": lambda: hnn.DissipativeHNN(4, WIDTH)}


def _tolerance(dtype: torch.dtype) -> float:
    """Closed form against autograd: four products of at most WIDTH terms each, rounded in another order,
    so each may differ by about WIDTH eps of its terms' size."""
    return 4 * WIDTH * torch.finfo(dtype).eps


@pytest.mark.parametrize("kind", sorted(_KINDS))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_working_arrays_kept_across_batch_sizes_leave_no_trace(kind, dtype):
    """One kernel called on growing and shrinking batches (an adaptive rollout's rows finish) gives each
    batch the bits a fresh kernel gives it, leaves earlier answers untouched, and agrees with autograd."""
    torch.manual_seed(0)
    model = _KINDS[kind]().to(dtype)
    sizes = [0, 15, 1, 64, 3, 40, 1, 0, 15, 64, 5, 4]
    states = [torch.randn(n, 4, dtype=dtype, generator=torch.Generator().manual_seed(i)) for i, n in enumerate(sizes)]
    with torch.no_grad(), hnn.modes.frozen_weights():
        answers = [model.time_derivative(x) for x in states]
        kept = [a.clone() for a in answers]
    for x, answer, first in zip(states, answers, kept, strict=True):
        assert torch.equal(answer, first)                              # not overwritten by a later call
        with torch.no_grad(), hnn.modes.frozen_weights():
            assert torch.equal(model.time_derivative(x), answer)       # a fresh kernel: the same bits
        reference = model.time_derivative(x.clone().requires_grad_(True)).detach()   # the training path
        tol, scale = _tolerance(dtype), (reference.abs().max().item() if len(x) else 1.0)    # an empty batch too
        assert answer.shape == x.shape
        torch.testing.assert_close(answer, reference, rtol=tol, atol=tol * scale)


def test_the_kernel_declines_what_it_does_not_serve():
    torch.manual_seed(0)
    model = hnn.build_model(4, WIDTH).double()
    kernel = EvaluationKernel(mlp_weights(model.differentiable_model), (1,), model._fold((1,)))
    x = torch.randn(5, 4, dtype=torch.float64)
    for declined in (x[None], x.float(), x[:, :3], torch.randn(KERNEL_MAX_ROWS + 1, 4, dtype=torch.float64),
                     x.to("meta"), torch._neg_view(x)):
        assert kernel.evaluate(declined) is None
    served = kernel.evaluate(x.clone().requires_grad_(True))      # no graph wanted: served, detached
    assert not served.requires_grad and torch.equal(served, kernel.evaluate(x))
    assert torch.equal(kernel.evaluate(x.T.contiguous().T), kernel.evaluate(x))     # a strided view
    reference = model.time_derivative(x.clone().requires_grad_(True)).detach()
    with torch.no_grad(), hnn.modes.frozen_weights():            # a declined state takes the general path
        for y in (torch._neg_view(-x), x):
            tol = _tolerance(torch.float64)
            torch.testing.assert_close(model.time_derivative(y), reference, rtol=tol, atol=tol * reference.abs().max().item())


def test_load_state_dict_between_rollouts_reaches_the_second():
    """The kernel copies the weights once per rollout: weights loaded between two rollouts are the
    second rollout's (as a training step's are, tests/test_models.py)."""
    torch.manual_seed(0)
    model, other = hnn.build_model(4, WIDTH).double(), hnn.build_model(4, WIDTH).double()
    x0 = torch.randn(3, 4, dtype=torch.float64)
    t = np.linspace(0.0, 1.0, 11)
    before = hnn.rollout(model.time_derivative, x0, t, method="dopri5", rtol=1e-9)
    model.load_state_dict(other.state_dict())
    after = hnn.rollout(model.time_derivative, x0, t, method="dopri5", rtol=1e-9)
    assert torch.equal(after, hnn.rollout(other.time_derivative, x0, t, method="dopri5", rtol=1e-9))
    assert not torch.allclose(after, before)


@pytest.mark.parametrize("kind", ["hnn", "baseline"])
@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_a_solver_stepping_in_numpy_calls_the_kernel_directly_with_the_same_bits(method, kind, monkeypatch):
    """An HNN's field carries the kernel's numpy call (``EnergyField.numpy``): the per-row solvers call it on
    their arrays, past the tensor conversions, and get the bits the tensor call gives; where the kernel does
    not serve the states (more than KERNEL_MAX_ROWS rows) the solver calls the field itself."""
    torch.manual_seed(0)
    model = _KINDS[kind]().double()         # the baseline's field is plain (no H) and carries the call too
    t = np.linspace(0.0, 2.0, 9)
    served = []
    real = EvaluationKernel.serve

    def counted(kernel, a):
        out = real(kernel, a)
        served.append(out is not None)
        return out
    monkeypatch.setattr(EvaluationKernel, "serve", counted)
    for rows in (1, 15, KERNEL_MAX_ROWS + 1):
        x0 = torch.randn(rows, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(rows))
        served.clear()
        direct = hnn.rollout(model, x0, t, method=method, rtol=1e-8, atol=1e-8)
        # past KERNEL_MAX_ROWS the first calls are the field's own (later ones may be served: finished rows drop)
        assert served and (all(served) if rows <= KERNEL_MAX_ROWS else not served[0])
        field = model.field
        field.numpy = None                  # the same field without the numpy call: the tensor path
        assert torch.equal(direct, hnn.rollout(field, x0, t, method=method, rtol=1e-8, atol=1e-8))
