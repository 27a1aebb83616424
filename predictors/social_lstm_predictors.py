"""The predictor classes of the ``SocialLSTM`` net (``predictors.nets.social_lstm``): ``SocialLSTMPredictor``
(Social-LSTM with grid or soft pooling, or the vanilla LSTM) and ``SocialGANPredictor`` (the Social-GAN-like
generator, deterministic as a ``Predictor``, with ``sample`` for its futures). Both are a
``predictors.learned.LearnedPredictor`` with a check of the net and a default model kind.
"""

from __future__ import annotations

import numpy as np
import torch

from predictors.base import OBS_LEN, check_rollout_inputs
from predictors.errors import PredictorError
from predictors.learned import LearnedPredictor
from predictors.nets.social_lstm import SocialLSTM
from predictors.threads import single_threaded


class SocialLSTMPredictor(LearnedPredictor):
    """Social-LSTM (``pooling`` "grid" or "soft") or, with ``pooling="none"``, the vanilla LSTM."""

    def __init__(self, net: SocialLSTM, *, name: str, obs_len: int = OBS_LEN, kind: str | None = None):
        if net.config.noise_dim:
            raise PredictorError("SocialLSTMPredictor takes a net without noise; use SocialGANPredictor")
        default = "vanilla_lstm" if net.config.pooling == "none" else "social_lstm"
        super().__init__(net, name=name, obs_len=obs_len, kind=kind or default)


class SocialGANPredictor(LearnedPredictor):
    """Social-GAN-like generator: deterministic (zero noise) ``rollout``/``to_casadi``, plus ``sample``."""

    default_kind = "social_gan"

    def __init__(self, net: SocialLSTM, *, name: str, obs_len: int = OBS_LEN, kind: str | None = None):
        if not getattr(net.config, "noise_dim", 0):
            raise PredictorError("SocialGANPredictor needs a generator net (noise_dim >= 1)")
        super().__init__(net, name=name, obs_len=obs_len, kind=kind)

    def sample(
        self,
        history: np.ndarray,
        mask: np.ndarray,
        robots_future: np.ndarray | None,
        humans: np.ndarray,
        horizon: int | None,
        k: int,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """``k`` futures, each with its own standard normal noise: ``(k, H, N_h, 2)``."""
        if k < 1:
            raise ValueError(f"k must be >= 1, got {k}")
        plans = None if robots_future is None else np.asarray(robots_future, dtype=np.float64)  # as rollout
        horizon = check_rollout_inputs(np.asarray(history), np.asarray(mask), plans, humans, horizon)
        pos, seen, n_humans = self._prepare(history, mask, humans, keep_robots=plans is not None)
        noise = torch.from_numpy(rng.standard_normal((k, pos.shape[1], self.config.noise_dim)))
        future = None if plans is None else torch.from_numpy(plans)[None].expand(k, -1, -1, -1)
        with torch.no_grad(), single_threaded():
            out = self._rollout_tensor(
                torch.from_numpy(pos)[None].expand(k, -1, -1, -1),
                torch.from_numpy(seen)[None].expand(k, -1, -1),
                n_humans,
                future,
                horizon,
                noise,
            )
        return out.numpy()
