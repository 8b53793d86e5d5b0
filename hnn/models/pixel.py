"""The paper's pixel model: an autoencoder whose latent z = [q, p] moves by an HNN (or the baseline)."""
from __future__ import annotations

import torch
from torch import nn

from ..interface import Model
from ..settings import RunSettings
from .hamiltonian import build_model
from .mlp import get_nonlinearity

class MLPAutoencoder(nn.Module):
    """The paper's pixel autoencoder: 4 layers each side, residual hidden layers, linear ends.

    Encoder ``(batch, input_dim) -> (batch, latent_dim)``: h = s(L1 x); h += s(L2 h); h += s(L3 h);
    z = L4 h. The decoder mirrors it back to ``input_dim`` (no output squashing). All 8 layers
    have biases and orthogonal weights.
    """

    def __init__(self, input_dim: int, hidden_dim: int, latent_dim: int, nonlinearity: str = "relu"):
        super().__init__()
        for label, value in (("input_dim", input_dim), ("hidden_dim", hidden_dim), ("latent_dim", latent_dim)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"MLPAutoencoder {label} must be a positive integer, got {value!r}")
        self._act = get_nonlinearity(nonlinearity)
        self.input_dim, self.latent_dim = input_dim, latent_dim
        self.encoder = nn.ModuleList([nn.Linear(input_dim, hidden_dim), nn.Linear(hidden_dim, hidden_dim),
                                      nn.Linear(hidden_dim, hidden_dim), nn.Linear(hidden_dim, latent_dim)])
        self.decoder = nn.ModuleList([nn.Linear(latent_dim, hidden_dim), nn.Linear(hidden_dim, hidden_dim),
                                      nn.Linear(hidden_dim, hidden_dim), nn.Linear(hidden_dim, input_dim)])
        for layer in (*self.encoder, *self.decoder):
            nn.init.orthogonal_(layer.weight)

    def _run(self, layers: nn.ModuleList, x: torch.Tensor) -> torch.Tensor:
        h = self._act(layers[0](x))
        h = h + self._act(layers[1](h))
        h = h + self._act(layers[2](h))
        return layers[3](h)

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """Pixels ``(batch, input_dim)`` -> latents ``(batch, latent_dim)``."""
        if x.dim() != 2 or x.shape[1] != self.input_dim:
            raise ValueError(f"expected pixels of shape (batch, {self.input_dim}), got {tuple(x.shape)}")
        return self._run(self.encoder, x)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Latents ``(batch, latent_dim)`` -> pixels ``(batch, input_dim)``."""
        if z.dim() != 2 or z.shape[1] != self.latent_dim:
            raise ValueError(f"expected latents of shape (batch, {self.latent_dim}), got {tuple(z.shape)}")
        return self._run(self.decoder, z)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.decode(self.encode(x))


class PixelHNN(Model):
    """An autoencoder whose latent z = [q, p] moves by an HNN (or, as the baseline, by a plain MLP).

    It is trained by ``hnn.objectives.pixel_loss(model, x, x_next)``, the paper's per-sample
    objective for a pair of pixel observations one frame apart: reconstruction + canonical-coordinate
    term + 0.1 x the latent-dynamics term, where the latent moves by one step of size 1 (one frame)
    of ``time_derivative``. Its ``time_derivative`` reads latents.
    """
    coordinates = "latent"
    conservative = True

    def __init__(self, input_dim: int, latent_dim: int = 2, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity,
                 baseline: bool = False, field_type: str = RunSettings.field_type,
                 autoencoder_nonlinearity: str = "relu"):
        super().__init__()
        if latent_dim % 2:
            raise ValueError(f"latent_dim must be even (z = [q, p]), got {latent_dim}")
        self.autoencoder = MLPAutoencoder(input_dim, hidden_dim, latent_dim, autoencoder_nonlinearity)
        self.hnn = build_model(latent_dim, hidden_dim, nonlinearity, baseline, field_type)
        self.input_dim, self.latent_dim, self.baseline = input_dim, latent_dim, baseline
        if baseline:
            self.conservative = False

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        return self.autoencoder.encode(x)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        return self.autoencoder.decode(z)

    def time_derivative(self, z: torch.Tensor, t=None) -> torch.Tensor:
        """dz/dt per frame, ``(batch, latent_dim)``."""
        return self.hnn.time_derivative(z)

    def hamiltonian(self, z: torch.Tensor) -> torch.Tensor:
        """The learned H of latents ``(batch, latent_dim)``, ``(batch,)`` (HNN only)."""
        return self.hnn.hamiltonian(z)


    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The pixels one frame later: decode(z + dz/dt) with z = encode(x)."""
        z = self.encode(x)
        return self.decode(z + self.time_derivative(z))


class PixelBaseline(PixelHNN):
    """``PixelHNN`` whose latent moves by a plain MLP (the paper's pixel baseline): no H."""
    conservative = False

    def __init__(self, input_dim: int, latent_dim: int = 2, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity,
                 field_type: str = RunSettings.field_type, autoencoder_nonlinearity: str = "relu"):
        super().__init__(input_dim, latent_dim, hidden_dim, nonlinearity, True, field_type, autoencoder_nonlinearity)
