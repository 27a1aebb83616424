"""Social-GAN-like model (Gupta et al. 2018): a generator and a local trajectory discriminator.

The generator is ``SocialLSTM`` with ``noise_dim > 0`` and a point head: an LSTM encoder over displacements
with social pooling at every step, noise ``z`` added (through a bias-free linear map) to the decoder's
initial hidden state, and a decoder with pooling at every step, so that the robots' plans reach the humans'
predictions in a recursive rollout exactly as for Social-LSTM. ``z = 0`` gives the deterministic prediction
that is exported to CasADi. Training uses the variety (best-of-k) loss plus the adversarial loss.
"""

from __future__ import annotations

import numbers
from dataclasses import asdict, dataclass
from typing import Any, Final

import torch
from torch import nn

from predictors.errors import PredictorError, short_repr
from predictors.nets.social_lstm import SocialLSTMConfig

# The generator's settings beside SocialLSTMConfig's defaults: the social_gan model kind's defaults
# (predictors.models) and generator_config's.
GENERATOR_DEFAULTS: Final[dict[str, Any]] = {"pooling": "soft", "noise_dim": 8, "head": "point"}


def generator_config(**overrides: Any) -> SocialLSTMConfig:
    """The generator's ``SocialLSTMConfig``: ``GENERATOR_DEFAULTS`` with ``overrides``."""
    config = {**GENERATOR_DEFAULTS, **overrides}
    if config["noise_dim"] < 1:
        raise PredictorError(f"a generator needs noise_dim >= 1, got {config['noise_dim']}")
    return SocialLSTMConfig(**config)


@dataclass(frozen=True)
class DiscriminatorConfig:
    embedding_dim: int = 16
    hidden_dim: int = 32
    input_scale: float = 4.0

    def __post_init__(self):
        # The bounds of the generator's sizes (nets.social_lstm.SIZE_BOUNDS), for the same reason.
        for name in ("embedding_dim", "hidden_dim"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 1 <= value <= 4096:
                raise PredictorError(
                    f"discriminator {name} must be an integer in 1..4096, got {short_repr(value)}"
                )
        scale = self.input_scale
        if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not 0 < scale <= 1000:
            raise PredictorError(
                f"discriminator input_scale must be a number in (0, 1000], got {short_repr(scale)}"
            )

    def to_dict(self) -> dict:
        return asdict(self)


class Discriminator(nn.Module):
    """Scores one agent's whole trajectory (observed + future): a logit, high for "real"."""

    def __init__(self, config: DiscriminatorConfig = DiscriminatorConfig()):
        super().__init__()
        self.config = config
        self.embedding = nn.Linear(2, config.embedding_dim)
        self.lstm = nn.LSTM(config.embedding_dim, config.hidden_dim, batch_first=True)
        self.classifier = nn.Sequential(
            nn.Linear(config.hidden_dim, config.hidden_dim), nn.ReLU(), nn.Linear(config.hidden_dim, 1)
        )

    def forward(self, trajectory: torch.Tensor) -> torch.Tensor:
        """``trajectory`` (B, T, 2) positions -> logits (B,)."""
        displacement = (trajectory[:, 1:] - trajectory[:, :-1]) * self.config.input_scale
        _, (h, _) = self.lstm(torch.relu(self.embedding(displacement)))
        return self.classifier(h[-1]).squeeze(-1)
