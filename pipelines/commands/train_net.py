"""``crowdmpc train``'s network: the net config the command line asks for (--model, --net-config,
--pooling, --hidden-dim) and the loss it trains on (--loss, --variety-error), checked before Lightning is
imported or a data file read."""

from __future__ import annotations

import argparse
import json
from typing import Any

from pipelines.errors import PipelineError
from predictors.errors import DuplicateKey, PredictorError, unique_keys

# --net-config is a JSON object of a few hyper-parameters; a longer text is no config anyone types.
MAX_NET_CONFIG_CHARS = 65_536
VARIETY_ERRORS = ("distance", "squared")  # predictors.nets.losses.VARIETY_ERRORS, without importing torch


def loss_options(parser: argparse.ArgumentParser, resumed: str) -> None:
    """--loss and --variety-error, with no parser default (``resumed``: train's note that a resume left
    without one takes the run's)."""
    parser.add_argument(
        "--loss",
        choices=("gaussian", "l2"),
        default=None,
        help="training loss of a net with a Gaussian head: gaussian (its negative log-likelihood) or l2 (on "
        "its mean); a point head trains on l2 only, social_gan on its variety + adversarial loss (default: "
        "gaussian for Gaussian heads, l2 for point heads; with --resume, the run's)",
    )
    parser.add_argument(
        "--variety-error",
        choices=VARIETY_ERRORS,
        default=None,
        help="social_gan's best-of-k variety loss per scene: the sample of least mean distance to the truth, "
        "penalised by that distance (distance), or of least mean squared distance, penalised by it "
        "(squared, Social GAN's own) (default distance)" + resumed,
    )


def check_variety_error(args: argparse.Namespace) -> None:
    """PipelineError unless --variety-error is unset or one of ``VARIETY_ERRORS``: argparse's choices check
    it typed, not as a resume takes it from its run's (damaged) file."""
    if args.variety_error not in (None, *VARIETY_ERRORS):
        raise PipelineError(
            f"--variety-error must be one of {', '.join(VARIETY_ERRORS)}, got {args.variety_error!r}"
        )


def check_variety_error_applies(args: argparse.Namespace) -> None:
    """PipelineError when --variety-error is typed for a net that trains no best-of-k loss (only a GAN's
    ``GANModule`` reads it; any other would train as without it)."""
    from predictors.models import model_kind

    if args.variety_error is not None and not model_kind(args.model).adversarial:
        raise PipelineError(
            f"--variety-error does not apply to {args.model} (only a GAN trains on a best-of-k variety loss)"
        )


def net_config_of(args: argparse.Namespace, base: dict[str, Any] | None = None) -> tuple[str | None, Any]:
    """The pooling (None: the kind has none) and the network config the command line asks for: its options
    over ``base`` (a resumed run's recorded config), else over the kind's defaults."""
    from predictors.models import model_kind

    kind = model_kind(args.model)
    overrides: dict[str, Any] = {}
    if args.net_config is not None:
        overrides = parse_net_config(args.net_config)
    for option, key, value in (
        ("--pooling", "pooling", args.pooling),
        ("--hidden-dim", "hidden_dim", args.hidden_dim),
    ):
        if value is None:
            continue
        if not kind.has_field(key) or key in kind.defining:  # the kind fixes it: kinds.ModelKind.defining
            why = kind.defining.get(key) or (
                "it has no social pooling" if key == "pooling" else f"its config has no {key}"
            )
            raise PipelineError(f"{option} does not apply to {args.model} ({why})")
        if key in overrides:
            raise PipelineError(f"{option} and --net-config both set {key}; give it once")
        overrides[key] = value
    try:
        config = kind.config({**(base or {}), **overrides})
    except PredictorError as exc:
        named = str(exc) if str(exc).startswith(args.model) else f"{args.model}: {exc}"
        if args.net_config is None and not overrides and not base:  # its config class's own defaults
            raise PipelineError(
                f"{named}; give the values its config has no default for with --net-config '{{\"key\": ...}}'"
            ) from None
        options = (("--pooling", args.pooling), ("--hidden-dim", args.hidden_dim))
        given = [option for option, value in options if value is not None]
        source = "--net-config" if args.net_config is not None else " and ".join(given) or "the run's config"
        raise PipelineError(f"{source}: {named}") from None
    pooling = getattr(config, "pooling", None)
    return (pooling if isinstance(pooling, str) else None), config


def resumed_net_config(
    args: argparse.Namespace, recorded: dict[str, Any] | None, pooling: str | None, config: Any
) -> tuple[str | None, Any, bool]:
    """``(pooling, config, taken)``: on a resume, the net config the run was started with (``recorded``'s)
    with what --pooling, --hidden-dim and --net-config type over it, else the one the command line asks for
    (``pooling``, ``config``: ``net_config_of``'s); ``taken``: whether it differs from the latter (which a
    resume names). Over the run's config rather than the kind's defaults, so that a resume typing
    --hidden-dim alone keeps the run's soft pooling, and one typing a value other than the run's is refused
    by the checks of the resume naming it. A recorded config of another model, or one the kind now refuses,
    is not taken: those checks name the difference."""
    from predictors.models import model_kind

    held = recorded.get("net_config") if recorded is not None else None
    if not args.resume or not isinstance(held, dict):
        return pooling, config, False
    try:
        model_kind(args.model).config(held)
        run_pooling, run = net_config_of(args, base=held)
    except (PredictorError, PipelineError):  # the options were checked alone by the first net_config_of
        return pooling, config, False
    return run_pooling, run, run != config


def training_loss(args: argparse.Namespace, net_config: Any) -> str:
    """The loss the run trains on: --loss, else the one its net's head takes (gaussian for a Gaussian head,
    l2 for a point head); PipelineError when --loss names one the net does not train on (it was ignored:
    ``PredictorModule.model_step`` trains a point head on L2, the GAN on its own loss, whatever it says)."""
    from predictors.models import model_kind

    kind = model_kind(args.model)
    if kind.adversarial:
        if args.loss is not None:
            raise PipelineError(
                f"--loss does not apply to {args.model} (a GAN: it trains on its variety + adversarial loss)"
            )
        return "l2"
    try:
        head = kind.head_type(net_config)
    except PredictorError as exc:
        raise PipelineError(f"{args.model}: {exc}") from None
    if head != "point":  # "gaussian"; any other head is refused by the contract check as the net is built
        return str(args.loss or "gaussian")
    if args.loss == "gaussian":
        raise PipelineError(
            f"--loss gaussian does not apply to {args.model} (its head_type is 'point': it trains on l2)"
        )
    return "l2"


def trains_point_head(args: argparse.Namespace, net_config: Any) -> bool:
    """Whether the net trains a point head on L2 (``training_loss`` has read its head already)."""
    from predictors.models import model_kind

    kind = model_kind(args.model)
    return not kind.adversarial and kind.head_type(net_config) == "point"


def parse_net_config(text: str) -> dict[str, Any]:
    if len(text) > MAX_NET_CONFIG_CHARS:
        raise PipelineError(
            f"--net-config: {len(text)} characters, more than the {MAX_NET_CONFIG_CHARS} allowed"
        )
    try:  # a key typed twice: json kept the last without a word (the 64 of hidden_dim 32 then 64 trained)
        values = json.loads(text, object_pairs_hook=unique_keys)
    except DuplicateKey as exc:
        raise PipelineError(f"--net-config: {exc}") from None
    except ValueError as exc:  # JSONDecodeError, or an integer literal of more than 4300 digits
        raise PipelineError(f"--net-config: not valid JSON ({exc})") from None
    except RecursionError:
        raise PipelineError("--net-config: not valid JSON (nested too deeply)") from None
    if not isinstance(values, dict):
        raise PipelineError(
            f"--net-config must be a JSON object like '{{\"hidden_dim\": 64}}', got {text[:60]!r}"
        )
    return values
