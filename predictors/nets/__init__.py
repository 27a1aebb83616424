"""Plain ``torch.nn`` networks of the learned predictors; no Lightning, no CasADi (``predictors.export``
builds their CasADi side from their own methods)."""

from predictors.nets.social_gan import Discriminator, DiscriminatorConfig
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

__all__ = ["Discriminator", "DiscriminatorConfig", "SocialLSTM", "SocialLSTMConfig"]
