"""A hand-written CasADi twin of a ``nets.SocialLSTM``'s two halves, built from
``tests.predictors.handwritten.layers`` with the model's own weights (agents as columns, one MX graph each,
one step function ``_step``). The project exports its nets with ``predictors.export`` (no hand-written
twin); this one, written layer by layer, stays in the tests as an independent check of that export
(tests/predictors/test_export.py).

The encoder's twin (``encoder``) is meant to be evaluated numerically, as ``LearnedPredictor.encode`` is;
only the prediction horizon (``prediction``) is symbolic, as ``to_casadi``'s is.

Context layout (``encode``), agents ordered humans (as given) then robots (increasing index), ``D`` hidden:
``h (N, D) | c (N, D) | now (N, 2) | first (N_h, 2) | present (N)``, each block row-major: the decoder's
LSTM state, the agents' current positions, the humans' predicted positions at ``t+1`` (these depend on the
past only) and 1/0 for agents observed at the current step (only those are pooled as neighbours).
"""

from __future__ import annotations

import re

import casadi as ca
import numpy as np

from predictors.nets.social_lstm import N_TAGS, SocialLSTMConfig
from tests.predictors.handwritten import layers as cl


def casadi_name(text: str) -> str:
    """A valid CasADi function name: a letter first, then letters, digits and single underscores."""
    name = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", text)).strip("_")
    return name if name[:1].isalpha() else f"predictor_{name}"


class SocialLSTMTwin:
    """The symbolic side of a learned predictor: ``SocialLSTM``'s encoder and decoder as CasADi functions.

    ``weights`` is the net's ``state_dict`` as float64 numpy arrays: the graphs hold numbers, not the torch
    parameters, so training may go on with the net. ``name`` (the predictor's) names each function built.
    """

    def __init__(self, weights: dict[str, np.ndarray], config: SocialLSTMConfig):
        self._weights = weights
        self.config = config

    def context_size(self, n_humans: int, n_robots: int) -> int:
        n_agents = n_humans + n_robots
        return n_agents * (2 * self.config.hidden_dim + 2 + 1) + 2 * n_humans

    def prediction(self, name: str, n_humans: int, n_robots: int, horizon: int) -> ca.Function:
        """``f(context, robots_future) -> humans_future`` (see ``predictors.base``)."""
        d = self.config.hidden_dim
        n = n_humans + n_robots
        context = ca.MX.sym("context", self.context_size(n_humans, n_robots))
        robots_future = ca.MX.sym("robots_future", horizon * n_robots * 2)
        blocks = np.cumsum([0, n * d, n * d, 2 * n, 2 * n_humans, n])
        h = ca.reshape(context[blocks[0] : blocks[1]], d, n)  # column j = agent j (row-major (N, D) input)
        c = ca.reshape(context[blocks[1] : blocks[2]], d, n)
        now = ca.reshape(context[blocks[2] : blocks[3]], 2, n)
        first = ca.reshape(context[blocks[3] : blocks[4]], 2, n_humans)
        present = ca.reshape(context[blocks[4] : blocks[5]], 1, n)
        plan = [
            ca.reshape(robots_future[2 * n_robots * k : 2 * n_robots * (k + 1)], 2, n_robots)
            for k in range(horizon)
        ]

        previous = now
        current = ca.horzcat(first, plan[0])
        outputs = [first]
        for k in range(1, horizon):
            h, c, mean = self._decode_step(h, c, previous, current, present, n_humans)
            humans_next = current[:, :n_humans] + mean
            outputs.append(humans_next)
            previous, current = current, ca.horzcat(humans_next, plan[k])
        humans_future = ca.vertcat(*[ca.reshape(o, 2 * n_humans, 1) for o in outputs])
        return ca.Function(
            casadi_name(f"{name}_h{n_humans}_r{n_robots}_H{horizon}"),
            [context, robots_future],
            [humans_future],
            ["context", "robots_future"],
            ["humans_future"],
        )

    def encoder(self, name: str, n: int, length: int) -> ca.Function:
        """``encoder(positions, seen) -> (h, c, step)``: ``SocialLSTM.encode``'s twin (inputs and outputs as
        ``LearnedPredictor.casadi_encoder`` describes them)."""
        d = self.config.hidden_dim
        positions = ca.MX.sym("positions", 2 * n * length)
        seen = ca.MX.sym("seen", n * length)
        # Column t * N + j is agent j at step t (the row-major (L, N, 2) and (L, N) inputs).
        pos = ca.reshape(positions, 2, n * length)
        flags = ca.reshape(seen, 1, n * length)

        def at(t):
            return pos[:, t * n : (t + 1) * n]

        def seen_at(t):
            return flags[:, t * n : (t + 1) * n]

        h, c = self._tag_step("encoder", ca.DM.zeros(d, n), ca.DM.zeros(d, n), slot=0)
        for t in range(1, length):
            active = seen_at(t - 1) * seen_at(t)
            h, c = self._step("encoder", h, c, at(t - 1), at(t), neighbours=active, active=active)
        step = self._mean(h)
        h, c = self._tag_step("decoder", h, c, slot=1)
        if self.config.noise_dim:
            # The generator's first prediction comes from a decoder step (SocialLSTM.encode).
            if length > 1:
                active, previous = seen_at(length - 2) * seen_at(length - 1), at(length - 2)
            else:
                active, previous = ca.DM.zeros(1, n), at(length - 1)
            h, c = self._step("decoder", h, c, previous, at(length - 1), neighbours=active, active=active)
            step = self._mean(h)
        return ca.Function(
            casadi_name(f"{name}_encoder_n{n}_L{length}"),
            [positions, seen],
            [ca.reshape(h, d * n, 1), ca.reshape(c, d * n, 1), ca.reshape(step, 2 * n, 1)],
            ["positions", "seen"],
            ["h", "c", "step"],
        )

    def _decode_step(self, h, c, previous, current, present, n_humans):
        """The twin of ``SocialLSTM.decode_step``, agents as columns; returns the humans' mean step."""
        h, c = self._step("decoder", h, c, previous, current, neighbours=present)
        return h, c, self._mean(h[:, :n_humans])

    def _mean(self, h):
        """The head's mean step ``(2, N)``: the first two outputs of either head are the raw linear ones."""
        return cl.linear(h, self._weights["head.weight"][:2], self._weights["head.bias"][:2])

    def _lstm(self, cell: str, x, h, c, weight_ih: np.ndarray):
        w = self._weights
        return cl.lstm_cell(
            x, h, c, weight_ih, w[f"{cell}.weight_hh"], w[f"{cell}.bias_ih"], w[f"{cell}.bias_hh"]
        )

    def _tag_step(self, cell: str, h, c, slot: int):
        """The twin of ``SocialLSTM._tag_step``: every agent is updated."""
        column = self.config.embedding_dim - N_TAGS + slot
        # The one-hot tag times weight_ih is that weight's column; a (1, N) input of ones selects it exactly.
        weight_ih = self._weights[f"{cell}.weight_ih"][:, column : column + 1]
        return self._lstm(cell, ca.DM.ones(1, h.shape[1]), h, c, weight_ih)

    def _step(self, cell: str, h, c, previous, current, *, neighbours, active=None):
        """The twin of ``SocialLSTM.step`` (agents as columns): the new ``(h, c)``.

        ``neighbours`` (1, N) weights who may be pooled; ``active`` (1, N) of 0/1 marks the agents that move
        and are updated, None for all of them (a prediction step, whose graph then carries no masking).
        """
        w, cfg = self._weights, self.config
        displacement = current - previous
        if active is not None:
            displacement = displacement * ca.repmat(active, 2, 1)
        parts = [displacement]
        if cfg.pooling != "none":
            weights = cl.grid_cell_weights(
                current,
                cell_side=cfg.cell_side,
                grid_size=cfg.grid_size,
                soft=cfg.pooling == "soft",
                neighbour_weight=neighbours,
            )
            values = cl.linear(h, w["pool.hidden_encoding.weight"], w["pool.hidden_encoding.bias"])
            grid = cl.grid_pool(values, weights)
            parts.append(cl.relu(cl.linear(grid, w["pool.embedding.weight"], w["pool.embedding.bias"])))
        x = cl.relu(
            cl.linear(
                ca.vertcat(*parts) * cfg.input_scale, w["input_embedding.weight"], w["input_embedding.bias"]
            )
        )
        # The two tag slots of the embedding are zero at every step but the tag steps: drop their columns.
        h_new, c_new = self._lstm(cell, x, h, c, w[f"{cell}.weight_ih"][:, : cfg.embedding_dim - N_TAGS])
        if active is None:
            return h_new, c_new
        # torch.where(active, new, old): with weights of exactly 0 and 1 the blend reproduces it bit for bit.
        keep = ca.repmat(active, h.shape[0], 1)
        return keep * h_new + (1 - keep) * h, keep * c_new + (1 - keep) * c
