"""Plain ``torch.nn`` networks of the learned predictors; no Lightning, no CasADi (their twin is
``predictors.casadi_twin``)."""

from predictors.nets.social_gan import Discriminator, DiscriminatorConfig
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

__all__ = ["Discriminator", "DiscriminatorConfig", "SocialLSTM", "SocialLSTMConfig"]
