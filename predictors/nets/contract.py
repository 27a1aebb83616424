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

A net may define its own training ``forward(positions, mask, obs_len, pred_len, *, teacher_forcing)``
returning ``(outputs (B, pred_len, N, K), predicted (B, pred_len, N, 2))`` (``predictors.training``);
without one it is trained through ``nets.rollout``. ``check_step_contract`` and ``check_training_forward``
run a net once on a small synthetic batch and refuse, in one line, one that breaks this contract: a wrong
shape would otherwise broadcast silently (a one-column step moves x and y alike) or fail deep in a rollout.
"""

from __future__ import annotations

import copy
import inspect
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, ClassVar, Final, Literal, Protocol, runtime_checkable

import torch

from crowdsim.world import DT
from predictors.errors import PredictorError, short_repr
from predictors.threads import single_threaded

Head = Literal["gaussian", "point"]
HEADS: Final[tuple[str, ...]] = ("gaussian", "point")
GAUSSIAN_WIDTH: Final[int] = 5  # mean (2), sigmas (2), correlation: what losses.gaussian_nll reads
# The checks' synthetic batch: B and N differ, so a state laid out (N, B, ...) cannot pass as (B, N, ...).
CHECK_BATCH: Final[int] = 2
CHECK_AGENTS: Final[int] = 3
# The step contract is checked again with this many agents: a net that fits only N = 3 (an nn.Linear across
# the agents) passed, and failed in training's first real batch in a 75-line traceback.
OTHER_AGENTS: Final[int] = 5
TRAINING_FORWARD: Final[str] = (
    "forward(positions, mask, obs_len, pred_len, *, teacher_forcing) -> (outputs, predicted)"
)
SEE: Final[str] = "(see predictors/nets/contract.py)"


@runtime_checkable
class StepNet(Protocol):
    config_class: ClassVar[type]
    config: Any  # an instance of config_class

    @property
    def head_type(self) -> Head: ...

    def encode(self, positions: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, ...]: ...

    def decode_step(self, *state_and_inputs: torch.Tensor) -> tuple[torch.Tensor, ...]: ...


def synthetic_scene(
    length: int,
    *,
    agents: int = CHECK_AGENTS,
    dtype: torch.dtype = torch.float32,
    device: torch.device | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(positions (B, length, N, 2), mask (B, length, N))``: agents walking straight lines within a couple
    of metres of each other (pooling range), all observed. Deterministic: checking a net draws no random
    numbers, so a seeded training run trains the same weights with the check as without it."""
    # Ordinary tensors even under the caller's torch.inference_mode(): the in-place check (_unchanged) reads
    # their count of changes, which inference tensors do not keep (a RuntimeError on loading a zoo model).
    with torch.inference_mode(False):
        steps = torch.arange(length, dtype=dtype, device=device)[None, :, None, None] * DT
        starts = [[-1.5, 0.3], [1.5, -0.2], [0.2, -1.6], [-0.4, 1.7], [2.0, 1.1]][:agents]
        velocities = [[0.9, 0.0], [-0.9, 0.1], [0.1, 0.8], [0.2, -0.9], [-0.7, -0.5]][:agents]
        start = torch.tensor(starts, dtype=dtype, device=device)
        velocity = torch.tensor(velocities, dtype=dtype, device=device)
        shift = torch.arange(CHECK_BATCH, dtype=dtype, device=device)[:, None, None, None] * 0.1
        positions = start + steps * velocity + shift
        return positions, torch.ones(positions.shape[:3], dtype=torch.bool, device=device)


@contextmanager
def _probing(net: torch.nn.Module) -> Iterator[None]:
    """Eval mode (no dropout draws, no batch-norm statistics updated) without gradients, on one thread (a
    tiny batch: torch's pool made the check 100x slower on a shared CPU); every submodule's mode is restored
    after (a net may keep a frozen part in eval mode). Outside the caller's inference mode, if any: the state
    tensors encode makes are checked for in-place changes (_unchanged), which inference tensors cannot be."""
    modes = [(module, module.training) for module in net.modules()]
    net.eval()
    try:
        with torch.inference_mode(False), torch.no_grad(), single_threaded():
            yield
    finally:
        for module, training in modes:
            module.training = training


def _call(where: str, what: str, agents: int, function: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``function(*args, **kwargs)``; a net that fails on a well-formed batch is the net's fault: one line."""
    try:
        return function(*args, **kwargs)
    except PredictorError:
        raise
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise PredictorError(
            f"{where}: {what} failed on a synthetic batch (B={CHECK_BATCH}, N={agents}): "
            f"{type(exc).__name__}: {first[:200]} {SEE}"
        ) from None


def head_type_of(net: object, where: str) -> object:
    """``net.head_type``; a plugin's property that raises (any exception) is the net's fault: one line."""
    try:
        return getattr(net, "head_type", None)
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise PredictorError(
            f"{where}: reading head_type failed: {type(exc).__name__}: {first[:200]} {SEE}"
        ) from None


def _unchanged(
    where: str,
    what: str,
    agents: int,
    arguments: dict[str, torch.Tensor],
    function: Callable[..., Any],
    *args: Any,
    **kwargs: Any,
) -> Any:
    """``_call(where, what, function, *args, **kwargs)``, refusing a method that writes into a tensor it was
    handed (torch counts every in-place change of a tensor and its views in ``_version``): ``positions -=
    centre`` in ``encode`` changed the caller's tensor, in training the batch itself, so that a net trained
    and was validated on moved scenes without a word."""
    before = {name: tensor._version for name, tensor in arguments.items()}
    result = _call(where, what, agents, function, *args, **kwargs)
    changed = [name for name, tensor in arguments.items() if tensor._version != before[name]]
    if changed:
        raise PredictorError(
            f"{where}: {what} changed its argument {changed[0]} in place: the caller's tensor (in training, "
            f"the batch) changes with it; compute on a new tensor, x = x - v rather than x -= v {SEE}"
        )
    return result


def _head_type(net: torch.nn.Module, where: str) -> str:
    head = head_type_of(net, where)
    if head not in HEADS:
        raise PredictorError(f"{where}: head_type must be one of {list(HEADS)}, got {short_repr(head)} {SEE}")
    return str(head)


def _expected_out(head: str, lead: str) -> str:
    if head == "gaussian":
        return f"({lead}, {GAUSSIAN_WIDTH}) (mean step, sigmas, correlation)"
    return f"({lead}, K) with K >= 2 (out[..., :2] is the mean step)"


def _check_head(
    out: Any, lead: tuple[int, ...], head: str, dtype: torch.dtype, where: str, what: str
) -> None:
    """``out`` is ``(*lead, K)`` of ``dtype``, with K the head's width (at least the 2 of the mean step)."""
    names = "B, N" if len(lead) == 2 else "B, pred_len, N"
    sizes = ", ".join(f"{n}={v}" for n, v in zip(names.split(", "), lead, strict=True))
    if not isinstance(out, torch.Tensor):
        raise PredictorError(f"{where}: {what} must be a tensor, got {type(out).__name__} {SEE}")
    width = out.shape[-1] if out.dim() == len(lead) + 1 and tuple(out.shape[:-1]) == lead else None
    fits = width == GAUSSIAN_WIDTH if head == "gaussian" else width is not None and width >= 2
    if not fits:
        raise PredictorError(
            f"{where}: {what} must be of shape {_expected_out(head, names)} for a {head!r} head, got "
            f"{tuple(out.shape)} for {sizes} {SEE}"
        )
    if out.dtype != dtype:
        raise PredictorError(f"{where}: {what} must be {dtype} like the positions, got {out.dtype} {SEE}")


def _shape(value: Any) -> str:
    """A tensor's shape, or what else the net returned in its place."""
    return str(tuple(value.shape)) if isinstance(value, torch.Tensor) else type(value).__name__


def _split(result: Any, where: str, method: str, agents: int) -> tuple[list[torch.Tensor], Any]:
    """``(*state, out)`` of what ``method`` returned, each state tensor ``(B, N, ...)``."""
    if not (isinstance(result, tuple | list) and len(result) >= 2):
        got = f"{len(result)} values" if isinstance(result, tuple | list) else type(result).__name__
        raise PredictorError(
            f"{where}: {method} must return a tuple (*state, out) with at least one state tensor, got {got} "
            f"{SEE}"
        )
    *state, out = result
    for i, tensor in enumerate(state):
        if not isinstance(tensor, torch.Tensor) or tuple(tensor.shape[:2]) != (CHECK_BATCH, agents):
            raise PredictorError(
                f"{where}: {method}'s state tensor {i} must be of shape (B, N, ...), got {_shape(tensor)} "
                f"for B={CHECK_BATCH}, N={agents} {SEE}"
            )
    return state, out


def _dtype_and_device(net: torch.nn.Module) -> tuple[torch.dtype, torch.device]:
    """What the net computes in: its first floating parameter's dtype and device (float32 on CPU if none)."""
    for p in net.parameters():
        if p.is_floating_point():
            return p.dtype, p.device
    return torch.float32, torch.device("cpu")


def check_step_contract(net: torch.nn.Module, where: str, *, obs_len: int, finite: bool = False) -> None:
    """PredictorError, one line starting with ``where`` (e.g. "model 'mymod:MyNet'"), unless ``net``'s
    ``encode`` and ``decode_step`` keep the step contract on a synthetic batch of ``obs_len`` steps: every
    state tensor ``(B, N, ...)``, ``decode_step`` handing back the state it was given in the same shapes and
    dtypes, ``out`` ``(B, N, K)`` in the positions' dtype with K the head's width. With ``finite`` (a net
    about to predict, not one about to train), both ``out`` must also be finite."""
    head = _head_type(net, where)
    for agents in (CHECK_AGENTS, OTHER_AGENTS):
        _check_steps(net, where, obs_len, head, agents, finite)


def check_predictor_contract(net: torch.nn.Module, where: str, *, obs_len: int) -> None:
    """``check_step_contract`` with finite outputs, for a net about to predict: training keeps a net whose
    outputs are NaN, its divergence told by the epoch's loss."""
    check_step_contract(net, where, obs_len=obs_len, finite=True)


def _check_finite(out: torch.Tensor, where: str, what: str, agents: int) -> None:
    """Every agent of the synthetic batch is observed, so no entry of ``out`` stands for padding: a NaN or
    inf there would be predicted in every closed-loop step, each of which then fell back to its safe plan,
    and the run ended 0 as the predictor's."""
    bad = ~torch.isfinite(out)
    if bool(bad.any()):
        raise PredictorError(
            f"{where}: {what} holds NaN or inf in {int(bad.sum())} of {out.numel()} entries on a synthetic "
            f"batch (B={CHECK_BATCH}, N={agents}) where every agent is observed; a predictor must return "
            f"finite outputs there {SEE}"
        )


def _check_same(out: torch.Tensor, again: torch.Tensor, where: str, method: str) -> None:
    """A net that draws a random number as it predicts (``torch.randn_like``, Python's ``random``) was added
    to a zoo, and evaluate and calibrate scored another draw at each run without a word; the closed loop
    planned with it in torch, since its export is refused. Within a float32 rounding or so, not bit for bit:
    a BLAS may sum in another order for another buffer's alignment (MKL's run-to-run note), where a draw
    moves an out by far more."""
    if not torch.allclose(out, again, rtol=1e-5, atol=1e-6):
        drift = float((out - again).abs().max())
        raise PredictorError(
            f"{where}: {method} is not deterministic: two calls on the same synthetic batch gave outs "
            f"{drift:.2e} apart; a predictor must predict the same steps from the same past (draw random "
            f"numbers only while training: if self.training) {SEE}"
        )


def _check_steps(
    net: torch.nn.Module, where: str, obs_len: int, head: str, agents: int, finite: bool = False
) -> None:
    """``check_step_contract`` on a synthetic batch of ``agents`` agents."""
    dtype, device = _dtype_and_device(net)
    positions, mask = synthetic_scene(obs_len, agents=agents, dtype=dtype, device=device)
    lead = (CHECK_BATCH, agents)
    step_net: Any = net  # its encode and decode_step are no nn.Module methods mypy knows
    with _probing(net):
        arguments = {"positions": positions, "mask": mask}
        encoded = _unchanged(where, "encode", agents, arguments, step_net.encode, positions, mask)
        state, out = _split(encoded, where, "encode", agents)
        _check_head(out, lead, head, dtype, where, "encode's out")
        # copies, not views of positions: a view shares its base's count of changes, and would be named too
        inputs = (positions[:, -2].clone(), positions[:, -1].clone(), mask[:, -1].clone())
        arguments = {f"state tensor {i}": t for i, t in enumerate(state)}
        arguments.update(zip(("prev", "cur", "neighbours"), inputs, strict=True))
        stepped = _unchanged(where, "decode_step", agents, arguments, step_net.decode_step, *state, *inputs)
        new_state, new_out = _split(stepped, where, "decode_step", agents)
        _check_head(new_out, lead, head, dtype, where, "decode_step's out")
        if finite:
            _check_finite(out, where, "encode's out", agents)
            _check_finite(new_out, where, "decode_step's out", agents)
            again = _split(step_net.encode(positions, mask), where, "encode", agents)
            _check_same(out, again[1], where, "encode")
            stepped = step_net.decode_step(*state, *inputs)  # inputs unchanged: _unchanged checked them
            _check_same(new_out, _split(stepped, where, "decode_step", agents)[1], where, "decode_step")
    before = [(tuple(t.shape), t.dtype) for t in state]
    after = [(tuple(t.shape), t.dtype) for t in new_state]
    if before != after:
        raise PredictorError(
            f"{where}: decode_step must return the state it is given, in the same shapes and dtypes: encode "
            f"gave {_describe(before)}, decode_step returned {_describe(after)} {SEE}"
        )


def check_step_contract_in_float64(net: torch.nn.Module, where: str, *, obs_len: int) -> None:
    """``check_step_contract`` on a float64 copy of ``net``, as ``LearnedPredictor`` runs it in the closed
    loop and the export: a step that casts its output or its state (``out.float()``) keeps the contract in the
    float32 it trains in, and was refused only when the trained weights were loaded, after the whole run."""
    if _dtype_and_device(net)[0] == torch.float64:
        return  # the check in the net's own dtype was this one
    twin = copy.deepcopy(net).to(torch.float64)
    where = f"{where} in float64 (as the closed loop and the export run it)"
    check_step_contract(twin, where, obs_len=obs_len)


def _describe(state: list[tuple[tuple[int, ...], torch.dtype]]) -> str:
    return "[" + ", ".join(f"{shape} {str(dtype).removeprefix('torch.')}" for shape, dtype in state) + "]"


def _bare(signature: inspect.Signature) -> str:
    """``(positions, mask)``: the parameters without their annotations, which only lengthen the line."""
    empty = inspect.Parameter.empty
    parameters = [p.replace(annotation=empty) for p in signature.parameters.values()]
    return str(signature.replace(parameters=parameters, return_annotation=empty))


def check_training_forward(net: torch.nn.Module, where: str, *, obs_len: int, pred_len: int) -> None:
    """PredictorError, one line, unless the net's own ``forward`` is the training rollout: it takes
    ``TRAINING_FORWARD``'s arguments (as ``PredictorModule.rollout`` passes them) and returns
    ``(outputs (B, pred_len, N, K), predicted (B, pred_len, N, 2))`` on a synthetic batch."""
    head = _head_type(net, where)
    dtype, device = _dtype_and_device(net)
    positions, mask = synthetic_scene(obs_len + pred_len, dtype=dtype, device=device)
    args = (positions, mask, obs_len, pred_len)
    signature = inspect.signature(net.forward)
    try:
        signature.bind(*args, teacher_forcing=True)
    except TypeError:
        raise PredictorError(
            f"{where}: {type(net).__name__}.forward{_bare(signature)} is not the training "
            f"rollout {TRAINING_FORWARD}; give it that signature, or drop forward and the net is trained "
            "through the generic rollout of encode and decode_step (predictors/nets/rollout.py)"
        ) from None
    with _probing(net):
        arguments = {"positions": positions, "mask": mask}
        result = _unchanged(where, "forward", CHECK_AGENTS, arguments, net, *args, teacher_forcing=True)
    if not (isinstance(result, tuple | list) and len(result) == 2):
        raise PredictorError(
            f"{where}: forward must return (outputs, predicted), got {type(result).__name__} {SEE}"
        )
    outputs, predicted = result
    lead = (CHECK_BATCH, pred_len, CHECK_AGENTS)
    _check_head(outputs, lead, head, dtype, where, "forward's outputs")
    if not isinstance(predicted, torch.Tensor) or tuple(predicted.shape) != (*lead, 2):
        raise PredictorError(
            f"{where}: forward's predicted positions must be of shape (B, pred_len, N, 2), got "
            f"{_shape(predicted)} for B={CHECK_BATCH}, pred_len={pred_len}, N={CHECK_AGENTS} {SEE}"
        )


def check_trainable(net: torch.nn.Module, where: str) -> None:
    """PredictorError, one line, unless ``net`` can be trained on the data module's batches: it has
    parameters to train, and they are float32 like the batches (a ``.double()`` net passed the step check,
    which runs in the net's own dtype, then failed in the first batch with a dtype mismatch)."""
    parameters = [p for p in net.parameters() if p.requires_grad]
    if not parameters:
        raise PredictorError(f"{where}: the net has no trainable parameters (nothing to optimise) {SEE}")
    other = sorted({str(p.dtype) for p in parameters if p.is_floating_point() and p.dtype != torch.float32})
    if other:
        raise PredictorError(
            f"{where}: parameters of {', '.join(other)}; training feeds float32 batches, so keep the net in "
            f"float32 (the closed loop evaluates it in float64 itself) {SEE}"
        )
