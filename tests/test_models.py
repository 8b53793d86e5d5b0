"""The HNN's vector field against analytic Hamiltonians, and the closed form against autograd."""
import math

import pytest
import torch

import hnn
import hnn.models
import hnn.models.tanh_mlp
from hnn.models.mlp import input_gradient


class ExactH(torch.nn.Module):
    """Stands in for the MLP: outputs (F1, F2) = (0, H(x)) for a known H."""

    def __init__(self, H):
        super().__init__()
        self.H = H
        self.dummy = torch.nn.Parameter(torch.zeros(()))  # models are expected to have parameters

    def forward(self, x):
        return torch.stack([torch.zeros_like(x[:, 0]), self.H(x)], dim=1)


def _grid(n=64):
    g = torch.linspace(-2.5, 2.5, n, dtype=torch.float64)
    q, p = torch.meshgrid(g, g, indexing="ij")
    return torch.stack([q.flatten(), p.flatten()], dim=1)


@pytest.mark.parametrize("task, analytic", [
    ("spring", lambda q, p: torch.stack([2 * p, -2 * q], 1)),
    ("pend", lambda q, p: torch.stack([2 * p, -3 * torch.sin(q)], 1)),
])
def test_symplectic_gradient_of_exact_hamiltonian(task, analytic):
    system = hnn.load_task(task)
    model = hnn.HNN(2, ExactH(system.hamiltonian))
    x = _grid()
    expected = analytic(x[:, 0], x[:, 1])
    torch.testing.assert_close(model.time_derivative(x), expected, rtol=1e-14, atol=1e-14)
    with torch.no_grad():
        torch.testing.assert_close(model.time_derivative(x), expected, rtol=1e-14, atol=1e-14)
    # the task's own dynamics agree with its Hamiltonian
    torch.testing.assert_close(system.dynamics(x), expected, rtol=1e-14, atol=1e-14)


def test_four_dimensional_canonical_field():
    # H = |q|^2 / 2 + |p|^2 / 2 in 2 degrees of freedom: dq/dt = p, dp/dt = -q, componentwise
    model = hnn.HNN(4, ExactH(lambda x: 0.5 * (x ** 2).sum(1)))
    x = torch.randn(10, 4, dtype=torch.float64)
    torch.testing.assert_close(model.time_derivative(x), torch.cat([x[:, 2:], -x[:, :2]], 1))


@pytest.fixture(params=["torch.tanh", "2 sigmoid(2a) - 1"])
def tanh_path(request, monkeypatch):
    """Run a test with the MLPs' tanh taking each of its two ways, whatever the tensors' sizes."""
    monkeypatch.setattr(hnn.models.tanh_mlp, "_FAST_TANH_MIN_ELEMENTS", 10 ** 9 if request.param == "torch.tanh" else 0)
    return request.param


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_mlps_tanh_is_tanh(tanh_path, dtype):
    # 2 sigmoid(2a) - 1 against tanh in float64: sigmoid = 1 / (1 + exp(-2a)) carries exp's error (1 ulp, times
    # 1 - sigmoid) and two roundings, 2 eps sigmoid (2 - sigmoid) <= 2 eps after the doubling; the subtraction of
    # 1 is exact for sigmoid >= 1/4 (Sterbenz) and rounds by eps / 2 below: 2.5 eps. 3 eps leaves half an ulp
    # for an exp not within 1 ulp (measured 1.5 eps with torch's scalar, AVX2 and AVX-512 kernels; the old
    # bound, 2e-7 in float32, was 1.7 eps: 1.1x above one box's worst point)
    tolerance = 3 * torch.finfo(dtype).eps
    a = torch.linspace(-12, 12, 200_001, dtype=dtype)
    with torch.no_grad():       # with grad on, an input that needs none takes torch.tanh (safe inside jvp)
        fast = hnn.models.tanh_mlp.fast_tanh(a)
    for out in (fast, hnn.models.tanh_mlp.fast_tanh_(a.clone())):
        assert (out.double() - torch.tanh(a.double())).abs().max() <= tolerance
        if tanh_path == "torch.tanh":
            assert torch.equal(out, torch.tanh(a))
        elif dtype == torch.float32:        # the fast way really ran: it rounds differently
            assert not torch.equal(out, torch.tanh(a))


def test_the_mlps_tanh_differentiates_twice_as_torch_tanh(tanh_path):
    a = torch.randn(6, 5, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(hnn.models.tanh_mlp.fast_tanh, (a,))
    assert torch.autograd.gradgradcheck(hnn.models.tanh_mlp.fast_tanh, (a,))
    g, = torch.autograd.grad(hnn.models.tanh_mlp.fast_tanh(a).sum(), a, create_graph=True)
    g_ref, = torch.autograd.grad(torch.tanh(a).sum(), a, create_graph=True)
    torch.testing.assert_close(g, g_ref, rtol=1e-14, atol=1e-15)
    torch.testing.assert_close(torch.autograd.grad(g.pow(2).sum(), a)[0],
                               torch.autograd.grad(g_ref.pow(2).sum(), a)[0], rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("field_type", ["solenoidal", "conservative", "both"])
@pytest.mark.parametrize("dim", [2, 4])
def test_closed_form_matches_autograd_values_and_all_gradients(field_type, dim, tanh_path):
    model = hnn.build_model(dim, 32, field_type=field_type).double()
    net = model.differentiable_model
    x = torch.randn(50, dim, dtype=torch.float64, requires_grad=True)
    target = torch.randn(50, dim, dtype=torch.float64)

    def reference(x):
        out = net(x)
        fields = []
        if field_type != "solenoidal":
            fields.append(torch.autograd.grad(out[:, 0].sum(), x, create_graph=True)[0])
        if field_type != "conservative":
            g = torch.autograd.grad(out[:, 1].sum(), x, create_graph=True)[0]
            fields.append(torch.cat([g[:, dim // 2:], -g[:, :dim // 2]], 1))
        return sum(fields)

    ours, ref = model.time_derivative(x), reference(x)
    torch.testing.assert_close(ours, ref, rtol=1e-12, atol=1e-13)
    params = list(model.parameters()) + [x]
    g_ours = torch.autograd.grad(((ours - target) ** 2).sum(), params)
    g_ref = torch.autograd.grad(((ref - target) ** 2).sum(), params)
    for a, b in zip(g_ours, g_ref):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)


def test_closed_form_is_used_and_gradcheck(tanh_path):
    # gradcheck compares the hand-written backward with finite differences, in float64
    net = hnn.MLP(2, 6, 2).double()
    x = torch.randn(5, 2, dtype=torch.float64, requires_grad=True)
    W1, b1, W2, b2, W3 = (p.detach().clone().requires_grad_(True) for p in net.parameters())
    from hnn.models.tanh_mlp import closed_form_input_gradient
    assert torch.autograd.gradcheck(closed_form_input_gradient, (x, W1, b1, W2, b2, W3[1]))


def test_the_closed_form_of_a_group_is_each_models_own_and_gradchecks(tanh_path):
    # the same function with a leading model axis: each slice is that model's lone closed form, in
    # value and in every gradient, and the batched backward passes gradcheck on its own
    from hnn.models.tanh_mlp import closed_form_input_gradient
    gen = torch.Generator().manual_seed(3)
    G, N, n, H = 3, 5, 4, 6
    args = [torch.randn(*shape, generator=gen, dtype=torch.float64)
            for shape in ((G, N, n), (G, H, n), (G, H), (G, H, H), (G, H), (G, H))]
    weights = [a.requires_grad_(True) for a in args[1:]]
    together = closed_form_input_gradient(args[0], *weights)
    target = torch.randn(together.shape, generator=gen, dtype=torch.float64)
    grads = torch.autograd.grad(((together - target) ** 2).sum(), weights)
    for g in range(G):
        mine = [w[g].detach().clone().requires_grad_(True) for w in weights]
        alone = closed_form_input_gradient(args[0][g], *mine)
        torch.testing.assert_close(together[g], alone, rtol=1e-12, atol=1e-13)
        for a, b in zip(grads, torch.autograd.grad(((alone - target[g]) ** 2).sum(), mine)):
            torch.testing.assert_close(a[g], b, rtol=1e-10, atol=1e-12)
    with torch.no_grad():       # the evaluation path (no autograd node) gives the same values
        torch.testing.assert_close(closed_form_input_gradient(args[0], *weights), together, rtol=1e-12, atol=1e-13)
    G, N, n, H = 2, 3, 2, 3                                  # gradcheck at small sizes
    small = tuple(torch.randn(*shape, generator=gen, dtype=torch.float64, requires_grad=True)
                  for shape in ((G, N, n), (G, H, n), (G, H), (G, H, H), (G, H), (G, H)))
    assert torch.autograd.gradcheck(closed_form_input_gradient, small)


def _closed_form_calls(monkeypatch) -> list:
    """Spy on the closed form, both evaluation paths: the returned list grows by one per call (either grad mode)."""
    calls = []

    def spy_on(real):
        def spy(*args, **kwargs):
            calls.append(1)
            return real(*args, **kwargs)
        return spy
    for name in ("_closed_form",):
        monkeypatch.setattr(hnn.models.tanh_mlp, name, spy_on(getattr(hnn.models.tanh_mlp, name)))
    # the evaluation path of a few states (the rollout kernel)
    monkeypatch.setattr(hnn.models.tanh_mlp.EvaluationKernel, "numpy", spy_on(hnn.models.tanh_mlp.EvaluationKernel.numpy))
    return calls


def _autograd_field(net, x):
    """The symplectic gradient of F2 = net(x)[:, 1] by plain autograd, 2-D: ``(batch, 2)``."""
    x = x.detach().requires_grad_(True)
    g = torch.autograd.grad(net(x)[:, 1].sum(), x)[0]
    return torch.cat([g[:, 1:], -g[:, :1]], 1)


@pytest.mark.parametrize("grad_mode", [True, False])
def test_an_edited_mlp_forward_falls_back_to_autograd(monkeypatch, grad_mode):
    calls = _closed_form_calls(monkeypatch)
    torch.manual_seed(0)
    model = hnn.build_model(2, 16).double()
    x = torch.randn(5, 2, dtype=torch.float64)
    with torch.set_grad_enabled(grad_mode):
        fast = model.time_derivative(x)
    assert len(calls) == 1                                   # the unedited MLP takes the closed form
    torch.testing.assert_close(fast, _autograd_field(model.differentiable_model, x), rtol=1e-10, atol=1e-10)
    unedited = hnn.MLP.forward
    monkeypatch.setattr(hnn.MLP, "forward", lambda self, x: 2 * unedited(self, x))
    with torch.set_grad_enabled(grad_mode):
        edited = model.time_derivative(x)
    assert len(calls) == 1                                   # not again: the closed form is the old network's
    torch.testing.assert_close(edited, _autograd_field(model.differentiable_model, x), rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(edited, 2 * fast, rtol=1e-10, atol=1e-10)


def test_subclasses_hooks_and_other_activations_fall_back_to_autograd(monkeypatch):
    calls = _closed_form_calls(monkeypatch)

    class Shifted(hnn.MLP):
        def forward(self, x):
            return super().forward(x + 0.5)

    class Named(hnn.MLP):
        """A subclass that leaves forward alone keeps the closed form."""

    x = torch.randn(5, 2, dtype=torch.float64)
    hooked = hnn.MLP(2, 8, 2).double()
    hooked.register_forward_hook(lambda module, inputs, out: out ** 2)
    for net in (Shifted(2, 8, 2).double(), hooked, hnn.MLP(2, 8, 2, nonlinearity="softplus").double()):
        field = hnn.HNN(2, net).time_derivative(x)
        torch.testing.assert_close(field, _autograd_field(net, x), rtol=1e-12, atol=1e-12)
    assert calls == []
    net = Named(2, 8, 2).double()
    torch.testing.assert_close(hnn.HNN(2, net).time_derivative(x), _autograd_field(net, x), rtol=1e-10, atol=1e-10)
    assert len(calls) == 1


_KINDS = {"hnn": lambda: hnn.build_model(4, 32), "both": lambda: hnn.build_model(4, 32, field_type="both"),
          "baseline": lambda: hnn.build_model(4, 32, baseline=True), "separable": lambda: hnn.SeparableHNN(4, 32),
          "separable-wide": lambda: hnn.SeparableHNN(4, 80),
          "dissipative": lambda: hnn.DissipativeHNN(4, 32)}


@pytest.mark.parametrize("kind", sorted(_KINDS))
@pytest.mark.parametrize("dtype, rtol", [(torch.float32, 2e-6), (torch.float64, 1e-13)])
def test_the_evaluation_kernel_serves_a_few_states_and_agrees_with_the_training_path(monkeypatch, kind, dtype, rtol):
    torch.manual_seed(0)
    model = _KINDS[kind]().to(dtype)
    calls = {"kernel": 0}
    real = hnn.models.tanh_mlp.EvaluationKernel.numpy

    def spy(*args):
        calls["kernel"] += 1
        return real(*args)
    monkeypatch.setattr(hnn.models.tanh_mlp.EvaluationKernel, "numpy", spy)
    limit = hnn.models.tanh_mlp.KERNEL_MAX_ROWS
    for rows in (1, 15, limit, limit + 1):
        x = torch.randn(rows, 4, dtype=dtype)[:, [0, 2, 1, 3]]     # a strided view
        before = calls["kernel"]
        with torch.no_grad():
            assert model.time_derivative(x) is not None and calls["kernel"] == before   # outside a rollout: no kernel
            with hnn.modes.frozen_weights():                                      # as inside hnn.rollout
                fast = model.time_derivative(x)
        reference = model.time_derivative(x.clone().requires_grad_(True)).detach()   # the training path
        # the wide separable HNN runs its two networks as two kernels, the narrow one as one block network
        assert calls["kernel"] - before == ((2 if kind == "separable-wide" else 1) if rows <= limit else 0)
        assert fast.dtype == dtype and not fast.requires_grad
        torch.testing.assert_close(fast, reference, rtol=rtol, atol=rtol)


def test_a_rollout_after_training_rolls_out_the_trained_weights():
    """The kernel is built per rollout: training between two rollouts (fused Adam, which does not
    bump the parameters' version counters) reaches the second one."""
    torch.manual_seed(0)
    model = hnn.build_model(2, 16)
    x0 = torch.tensor([[0.3, 0.4], [-0.5, 0.2]])
    t = [0.0, 0.5, 1.0]
    before = hnn.rollout(model.time_derivative, x0, t, method="rk4", dt=0.1)
    x = torch.randn(64, 2)
    hnn.train(model, x, torch.cat([x[:, 1:], -x[:, :1]], 1), total_steps=20, progress=False)
    after = hnn.rollout(model.time_derivative, x0, t, method="rk4", dt=0.1)
    assert (after - before).abs().max() > 1e-3

    def autograd(y):
        with torch.enable_grad():
            y = y.detach().requires_grad_(True)
            g = torch.autograd.grad(model.differentiable_model(y)[:, 1].sum(), y)[0]
        return torch.cat([g[:, 1:], -g[:, :1]], 1)
    torch.testing.assert_close(after, hnn.rollout(autograd, x0, t, method="rk4", dt=0.1), rtol=1e-5, atol=1e-6)


def test_time_derivative_modes():
    model = hnn.build_model(2, 16)
    x = torch.randn(8, 2)
    with torch.no_grad():
        out = model.time_derivative(x)
    assert out.shape == (8, 2) and not out.requires_grad
    out = model.time_derivative(x)           # grad mode: differentiable w.r.t. the weights
    out.sum().backward()
    assert all(p.grad is not None for p in model.differentiable_model.linear2.parameters())
    z = torch.randn(8, 2, requires_grad=True)  # and w.r.t. an input that carries a graph
    (model.time_derivative(z * 2) ** 2).sum().backward()
    assert z.grad is not None and torch.isfinite(z.grad).all()


def test_time_derivative_finite_for_large_and_tiny_inputs():
    model = hnn.build_model(2, 32).double()
    for scale in (1e-30, 1e-8, 1.0, 1e4, 1e12):
        x = torch.randn(16, 2, dtype=torch.float64) * scale
        out = model.time_derivative(x)
        assert torch.isfinite(out).all(), scale
    # far from the data tanh saturates: the field goes to zero, not to NaN
    assert model.time_derivative(torch.full((1, 2), 1e12, dtype=torch.float64)).abs().max() < 1e-6


def test_baseline_predicts_dxdt_directly():
    model = hnn.build_model(4, 16, baseline=True)
    x = torch.randn(3, 4)
    torch.testing.assert_close(model.time_derivative(x), model.differentiable_model(x))
    with pytest.raises(ValueError, match="no Hamiltonian"):
        model.hamiltonian(x)


def test_mlp_is_the_papers():
    net = hnn.MLP(2, 200, 2)
    assert net.linear3.bias is None
    w = net.linear2.weight
    torch.testing.assert_close(w @ w.T, torch.eye(200), atol=1e-5, rtol=0)   # orthogonal init
    assert math.isclose(float(hnn.models.permutation_tensor(2)[0, 1]), 1.0)


def test_bad_input_gives_clear_errors():
    model = hnn.build_model(2, 8)
    with pytest.raises(ValueError, match=r"expected x of shape \(batch, 2\), got \(5, 3\)"):
        model.time_derivative(torch.randn(5, 3))
    with pytest.raises(ValueError, match=r"got \(2,\)"):
        model.time_derivative(torch.randn(2))
    with pytest.raises(ValueError, match="unknown nonlinearity 'gelu2'"):
        hnn.MLP(2, 8, 2, nonlinearity="gelu2")
    with pytest.raises(ValueError, match="unknown field_type 'curl'"):
        hnn.HNN(2, hnn.MLP(2, 8, 2), field_type="curl")
    with pytest.raises(ValueError, match="even input_dim"):
        hnn.HNN(3, hnn.MLP(3, 8, 2))
    with pytest.raises(ValueError, match="must output"):
        hnn.HNN(2, hnn.MLP(2, 8, 3))
    with pytest.raises(ValueError, match="must output"):
        hnn.HNN(2, torch.nn.Linear(2, 3)).time_derivative(torch.randn(4, 2))
    with pytest.warns(UserWarning, match="second derivative"):
        hnn.build_model(2, 8, nonlinearity="relu")


def test_autograd_path_for_other_nonlinearities_agrees_with_finite_differences():
    net = hnn.MLP(2, 16, 2, nonlinearity="softplus").double()
    x = torch.randn(4, 2, dtype=torch.float64)
    g = input_gradient(net, x, 1, create_graph=False)
    eps = 1e-6
    for j in range(2):
        e = torch.zeros(2, dtype=torch.float64)
        e[j] = eps
        fd = (net(x + e)[:, 1] - net(x - e)[:, 1]) / (2 * eps)
        torch.testing.assert_close(g[:, j], fd, rtol=1e-6, atol=1e-8)


def test_large_tanh_layers_differentiate_through_forward_mode_inside_a_recorded_graph(monkeypatch):
    """MechanicalHNN.observed_time_derivative takes a jvp of M^-1(q) while training records the graph:
    there tanh's input reports requires_grad=False, and the in-place fast tanh once clobbered a value
    the backward needed. Gradients must equal those of torch's own tanh (big batch: the fast path)."""
    import hnn.models.tanh_mlp as tanh_mlp

    def grads():
        torch.manual_seed(0)
        model = hnn.MechanicalHNN(4, hidden_dim=64, periodic=True)
        z = torch.randn(100, 4)                         # 100 x 64 = 6400 elements: past the fast tanh's threshold
        model.observed_time_derivative(z).pow(2).mean().backward()
        return [p.grad.clone() for p in model.parameters()]

    fast = grads()
    monkeypatch.setattr(tanh_mlp, "_FAST_TANH_MIN_ELEMENTS", 10 ** 9)   # torch.tanh everywhere
    for a, b in zip(fast, grads()):
        assert torch.allclose(a, b, rtol=1e-4, atol=1e-6)  # the two tanh formulas differ in the last bits


def test_gradient_of_is_the_analytic_gradient_and_keeps_a_graph_only_when_asked():
    # H = sum x^3 / 3 + x0 x1: dH/dx = x^2 + (x1, x0), d/dx of that again = 2x + swap
    x = torch.randn(4, 2, dtype=torch.float64)

    def H(x):
        return (x ** 3).sum(1) / 3 + x[:, 0] * x[:, 1]
    expected = x ** 2 + x.flip(1)
    with torch.no_grad():
        g = hnn.interface.gradient_of(H, x)
    torch.testing.assert_close(g, expected, rtol=1e-14, atol=0)
    assert not g.requires_grad
    x_in = x.clone().requires_grad_(True)
    g = hnn.interface.gradient_of(H, x_in)          # grad mode: a graph through x
    second, = torch.autograd.grad(g[:, 0].sum(), x_in)
    torch.testing.assert_close(second, torch.stack([2 * x[:, 0], torch.ones(4, dtype=x.dtype)], 1), rtol=1e-14, atol=0)
    assert not hnn.interface.gradient_of(H, x_in, create_graph=False).requires_grad


def test_the_inits_are_the_peers_own():
    """zero_bias: DGNet's orthogonal weights and zero biases; lnn: the LNN's custom_init, whose weight std is
    s / sqrt(n) with n the layer's larger side and s = 2.2, 0.58, n for the first, hidden and output layers;
    every MLP of a model (both of the separable kind's), drawn from the seeded global generator."""
    torch.manual_seed(0)
    built = hnn.models.SeparableHNN(4, 300)
    torch.manual_seed(0)
    zero = hnn.models.initialize(hnn.models.SeparableHNN(4, 300), "zero_bias")
    for before, after in zip(built.modules(), zero.modules()):
        if isinstance(after, torch.nn.Linear):
            assert after.bias is None or not after.bias.any()
            assert torch.equal(after.weight, before.weight)         # still the orthogonal draw
    torch.manual_seed(1)
    lnn = hnn.models.initialize(hnn.models.LagrangianNN(4, 300), "lnn")
    layers = (lnn.net.linear1, lnn.net.linear2, lnn.net.linear3)          # (300, 4), (300, 300), (1, 300)
    for layer, std in zip(layers, (2.2 / math.sqrt(300), 0.58 / math.sqrt(300), math.sqrt(300))):
        assert layer.weight.std().item() == pytest.approx(std, rel=0.1)     # 300 to 90000 draws each
        assert layer.bias is None or not layer.bias.any()
    torch.manual_seed(1)
    again = hnn.models.initialize(hnn.models.LagrangianNN(4, 300), "lnn")
    assert all(torch.equal(a, b) for a, b in zip(lnn.parameters(), again.parameters()))
    # a run's spec applies it after the kind's builder
    args = {"kind": "hnn", "input_dim": 2, "hidden_dim": 8, "init": "zero_bias"}
    assert not hnn.kinds.model_from_args(args).differentiable_model.linear1.bias.any()
    with pytest.raises(ValueError, match="unknown init 'xavier'; choose one of orthogonal, zero_bias, lnn"):
        hnn.models.initialize(built, "xavier")
