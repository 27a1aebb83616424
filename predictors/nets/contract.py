"""The step contract every predictor net keeps, shipped or plugin: what a network must offer to crowdmpc.

A predictor net is a ``torch.nn.Module`` that predicts one step at a time for every agent (Eq. (1)), with a
state it carries between steps (an LSTM's ``(h, c)``, a GRU's ``h``, a window of positions: any tensors):

* ``encode(positions, mask) -> (*state, out)``: the observed past, ``positions`` ``(B, L, N, 2)`` metres and
  ``mask`` ``(B, L, N)`` bool, to the state after the last observed step and the head output ``out``
  ``(B, N, K)`` whose ``out[..., :2]`` is the mean step to the first future position;
* ``decode_step(*state, prev, cur, neighbours) -> (*state, out)``: one prediction step from the agents'
  positions at the last two steps (``prev``, ``cur`` ``(B, N, 2)``); ``neighbours`` ``(B, N)`` bool marks who
  may be attended to or pooled (the agents observed at the current time). ``out[..., :2]`` is the mean step.

Every state tensor is ``(B, N, ...)``: one row of state per agent, so the recursion can feed the robots' plan
in. ``out`` with ``K = 5`` under ``head_type == "gaussian"`` is TrajNet++'s bivariate Gaussian (mean, sigmas,
correlation); ``K = 2`` (``"point"``) a point step.

``config_class`` is a frozen dataclass of the net's hyper-parameters (JSON values only), validated in
``__post_init__``; ``net_class(config_class(**values))`` builds the net. ``head_type`` decides the training
loss (it is not called ``head`` because nets name their output layer so, as TrajNet++ does).

Both methods are run by ``predictors.export`` on symbolic tensors to build the net's CasADi twin, so they may
use shapes in Python freely (``batch, n, _ = cur.shape``; loops over the observed steps) but must not branch
on tensor values, and must not write into tensors in place (``x[:, 0] = 1``).
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal, Protocol, runtime_checkable

import torch

Head = Literal["gaussian", "point"]


@runtime_checkable
class StepNet(Protocol):
    config_class: ClassVar[type]
    config: Any  # an instance of config_class

    @property
    def head_type(self) -> Head: ...

    def encode(self, positions: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, ...]: ...

    def decode_step(self, *state_and_inputs: torch.Tensor) -> tuple[torch.Tensor, ...]: ...
