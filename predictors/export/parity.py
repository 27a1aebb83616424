"""The check every export passes: the CasADi prediction against the torch rollout, values and Jacobians with
respect to the robots' plan, in float64 (``PARITY_TOLERANCE``), on two scenes: a crowd whose agents see each
other (``crossing_scene``), and one scattered over tens of metres with gaps in the history
(``scattered_scene``), as the simulator and the datasets give.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final, Protocol

import casadi as ca
import numpy as np
import torch

from crowdsim.world import DT
from predictors.export.errors import DETACHED, ExportError
from predictors.threads import single_threaded


class Exported(Protocol):
    """What the check needs of a predictor (``predictors.learned.LearnedPredictor`` has it all); a protocol
    and not that class, because the class calls this module on its first export."""

    name: str
    obs_len: int

    def to_casadi(self, n_humans: int, n_robots: int, horizon: int) -> Any: ...

    def encode(self, history: np.ndarray, mask: np.ndarray, humans: np.ndarray) -> np.ndarray: ...

    def rollout_tensor(
        self, history: np.ndarray, mask: np.ndarray, robots_future: Any, humans: np.ndarray
    ) -> torch.Tensor: ...


PARITY_TOLERANCE: Final[float] = 1e-6
# What the check compares, as Parity.nonfinite names them.
NONFINITE_ORDER: Final[tuple[str, ...]] = (
    "torch's prediction",
    "the export's prediction",
    "torch's Jacobian",
    "the export's Jacobian",
)


@dataclass(frozen=True)
class Parity:
    value_error: float  # max |CasADi - torch| over the predicted positions, metres
    jacobian_error: float  # max |dCasADi/dplan - dtorch/dplan|
    # which of torch's and the export's values and Jacobians hold NaN or inf (then an error above is NaN)
    nonfinite: tuple[str, ...] = ()
    # max |dtorch/dplan|: 0 when no prediction depends on the robots' plan, so that the Jacobians compared
    # were zeros on both sides (a net without social pooling, as vanilla_lstm)
    coupling: float = 0.0

    @property
    def worst(self) -> float:
        return max(self.value_error, self.jacobian_error)

    def ok(self, tolerance: float = PARITY_TOLERANCE) -> bool:
        # NaN fails every comparison, and max(0.0, nan) is 0.0: each error is checked on its own
        return all(math.isfinite(e) and e <= tolerance for e in (self.value_error, self.jacobian_error))


def crossing_scene(
    n_humans: int, n_robots: int, horizon: int, obs_len: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A plausible scene: agents within 3 m of each other (so pooling and attention see neighbours) walking
    at ~1 m/s, robot ``j`` ending its past within 1 m of human ``j mod N_h``, so that the prediction
    depends on the plan (robots 2.4-5.2 m from every human compared two zero Jacobians); ``(history (L, N,
    2), mask, humans, robots_future (H, M, 2))``, robots last."""
    rng = np.random.default_rng(seed)
    n = n_humans + n_robots
    start = rng.uniform(-3.0, 3.0, (n, 2))
    velocity = rng.normal(0.0, 1.0, (n, 2))
    steps = np.arange(obs_len)[:, None, None] * DT
    history = start[None] + steps * velocity[None] + rng.normal(0.0, 0.02, (obs_len, n, 2))
    if n_humans:
        near = np.random.default_rng([seed, 1]).uniform(-0.7, 0.7, (n_robots, 2))
        beside = history[-1, np.arange(n_robots) % n_humans] + near
        history[:, n_humans:] += (beside - history[-1, n_humans:])[None]
    future = (
        history[-1, n_humans:][None]
        + (np.arange(1, horizon + 1)[:, None, None] * DT) * velocity[None, n_humans:]
    )
    return history, np.ones((obs_len, n), dtype=bool), np.arange(n_humans), future


# Metres between neighbouring agents of scattered_scene: gates on distance saturate (a sigmoid of 4 - d^2
# has an argument beyond exp's range), pooling and attention find nobody.
SCATTER: Final[float] = 30.0


def scattered_scene(
    n_humans: int, n_robots: int, horizon: int, obs_len: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``crossing_scene`` with agent ``i`` moved ``SCATTER * i`` metres along x, and gaps in the humans'
    history: humans 0, 2, 4, ... are seen only from halfway through it, humans 1, 3, ... were last seen two
    steps ago (their current position is imputed) and, with 5 steps or more, miss one in the middle too. The
    robots are always seen, as in the simulator."""
    history, mask, humans, future = crossing_scene(n_humans, n_robots, horizon, obs_len, seed)
    offset = np.zeros((n_humans + n_robots, 2))
    offset[:, 0] = SCATTER * np.arange(n_humans + n_robots)
    history = history + offset[None]
    future = future + offset[None, n_humans:]
    half = obs_len // 2
    mask[:half, humans[0::2]] = False
    mask[max(1, obs_len - 2) :, humans[1::2]] = False  # every human stays seen at least once
    if obs_len >= 5:
        mask[half - 1, humans[1::2]] = False
    return history, mask, humans, future


def check_parity(predictor: Exported, n_humans: int, n_robots: int, horizon: int, seed: int = 0) -> Parity:
    """``to_casadi``'s function against ``rollout_tensor`` on ``crossing_scene`` and ``scattered_scene``: the
    worst error of each kind over both (NaN if either is)."""
    function = predictor.to_casadi(n_humans, n_robots, horizon)
    errors = [
        _errors(predictor, function, scene(n_humans, n_robots, horizon, predictor.obs_len, seed))
        for scene in (crossing_scene, scattered_scene)
    ]
    value_error, jacobian_error, coupling = (
        float(np.max(e)) for e in zip(*((e[0], e[1], e[3]) for e in errors), strict=True)
    )
    nonfinite = tuple(name for name in NONFINITE_ORDER if any(name in e[2] for e in errors))
    return Parity(value_error, jacobian_error, nonfinite, coupling)


def _errors(
    predictor: Exported, function: Any, scene: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
) -> tuple[float, float, tuple[str, ...], float]:
    """The largest differences of ``function``'s prediction and its Jacobian from torch's on ``scene``,
    which of the four (``NONFINITE_ORDER``) hold NaN or inf, and torch's largest Jacobian entry."""
    history, mask, humans, future = scene
    context = predictor.encode(history, mask, humans)
    plan = ca.MX.sym("plan", future.size)
    symbolic = function(context, plan)
    jacobian = ca.Function("parity_jacobian", [plan], [symbolic, ca.jacobian(symbolic, plan)])
    value, jac = (np.asarray(x) for x in jacobian(future.ravel()))

    def rollout(plan_t: torch.Tensor) -> torch.Tensor:
        return predictor.rollout_tensor(history, mask, plan_t.reshape(future.shape), humans).reshape(-1)

    plan_t = torch.from_numpy(future.ravel().copy())
    with single_threaded():  # one backward pass per output: torch's thread pool only spins on these sizes
        torch_value = rollout(plan_t).detach().numpy()
        torch_jac = (
            torch.autograd.functional.jacobian(rollout, plan_t, vectorize=True).numpy()
            if future.size
            else np.zeros((0, 0))
        )
    arrays = dict(zip(NONFINITE_ORDER, (torch_value, value, torch_jac, jac), strict=True))
    return (
        float(np.abs(value.ravel() - torch_value).max(initial=0.0)),
        float(np.abs(jac.reshape(torch_jac.shape) - torch_jac).max(initial=0.0)),
        tuple(name for name, array in arrays.items() if not np.isfinite(array).all()),
        float(np.abs(torch_jac).max(initial=0.0)),
    )


def require_parity(predictor: Exported, n_humans: int, n_robots: int, horizon: int) -> Parity:
    """``check_parity``, or ExportError when it exceeds ``PARITY_TOLERANCE``."""
    parity = check_parity(predictor, n_humans, n_robots, horizon)
    if any(name.startswith("torch's") for name in parity.nonfinite):
        # not a disagreement with torch: the net itself evaluates or differentiates where it cannot
        raise ExportError(
            f"{' and '.join(parity.nonfinite)} with respect to the robots' plan hold NaN or inf on the "
            "parity scenes: the net evaluates or differentiates an operation where it is infinite (sqrt "
            "of 0, as of an agent's squared distance to itself; 1/x or log at 0): keep its argument from 0 "
            "(a distance as torch.norm(d, dim=-1), whose gradient at 0 is 0, or sqrt(d2 + 1e-12)); masking "
            "the result afterwards (torch.where, * 0) still leaves NaN gradients",
            predictor.name,
        )
    if not parity.ok():
        if parity.value_error <= PARITY_TOLERANCE and math.isfinite(parity.jacobian_error):
            net = getattr(predictor, "net", None)
            detached = DETACHED.get(net) if net is not None else None
            raise ExportError(_derivatives_differ(parity, detached), predictor.name)
        drift = _torch_drift(predictor, n_humans, n_robots, horizon)
        if drift > PARITY_TOLERANCE:  # no export can match a net that is not one function of its inputs
            raise ExportError(
                f"torch's prediction is not deterministic: two rollouts of the same scene differ by "
                f"{drift:.2e}, and an exported function is one fixed draw of it; a net must predict the same "
                "steps from the same past (draw random numbers, by random, numpy or torch.rand*, only while "
                "training: if self.training)",
                predictor.name,
            )
        raise ExportError(
            f"the exported prediction differs from torch by {parity.value_error:.2e} (values) and "
            f"{parity.jacobian_error:.2e} (Jacobians), more than {PARITY_TOLERANCE:g}",
            predictor.name,
        )
    return parity


def _torch_drift(predictor: Exported, n_humans: int, n_robots: int, horizon: int) -> float:
    """The largest difference of two torch rollouts of the parity's first scene: not 0 for a net that draws
    a random number as it predicts, whose export (traced once: the draw a constant) then "differed from
    torch" as if the exporter were wrong. Run only once parity failed, so a passing export costs nothing."""
    history, mask, humans, future = crossing_scene(n_humans, n_robots, horizon, predictor.obs_len, 0)
    plan = torch.from_numpy(future.copy())
    with single_threaded(), torch.no_grad():
        first, second = (predictor.rollout_tensor(history, mask, plan, humans).numpy() for _ in range(2))
    return float(np.nan_to_num(np.abs(first - second), nan=np.inf).max(initial=0.0))


def _derivatives_differ(parity: Parity, detached: str | None) -> str:
    """Values that agree with Jacobians that do not: torch stops a gradient the export cannot stop."""
    agree = (
        f"the exported prediction agrees with torch ({parity.value_error:.2e}) but its Jacobians with respect"
        f" to the robots' plan differ by {parity.jacobian_error:.2e}, more than {PARITY_TOLERANCE:g}"
    )
    if detached is not None:
        return (
            f"detach() (in module {detached!r}) has no CasADi counterpart: the exported function would "
            f"differentiate through it; {agree}; detach only while training (if self.training), as the "
            "shipped nets do"
        )
    return (
        f"{agree}: usually a gradient torch stops and CasADi cannot, as a detach(), a torch.no_grad() "
        "block or a straight-through trick (x + (f(x) - x).detach()) stops it"
    )
