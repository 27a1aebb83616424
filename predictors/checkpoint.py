"""A checkpoint pair: ``NAME.pt`` (a plain ``state_dict`` of tensors, read with
``torch.load(..., weights_only=True)``, never a pickled object) and ``NAME.json`` (what to build: the model
kind of ``predictors.models``, its net's hyper-parameters, observed steps; ``"class"``, the predictor class,
is informational), and the checks every file of a zoo goes through (names, hashes, JSON documents, weights).

``predictors.zoo`` lists pairs in manifests; this module reads and writes one pair and trusts nothing in it.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Final, NamedTuple

from predictors.base import OBS_LEN
from predictors.errors import CheckpointMismatch, DuplicateKey, PredictorError, short_repr, unique_keys
from predictors.hashing import is_sha256, sha256_file

if TYPE_CHECKING:
    from collections.abc import Callable

    import torch

    from predictors.kinds import ModelKind
    from predictors.learned import LearnedPredictor

# The predictor classes a config's informational "class" may name: the generic one, the Social-LSTM class of
# the shipped checkpoints (written before model kinds), and the GAN generator's (a kind with ``adversarial``).
PREDICTOR_CLASS_NAMES: Final[tuple[str, ...]] = (
    "LearnedPredictor",
    "SocialLSTMPredictor",
    "SocialGANPredictor",
)
CONFIG_FORMAT: Final[str] = "crowdmpc-predictor"
# every key save_checkpoint writes: another is a typo whose setting would be silently left at its default
CONFIG_KEYS: Final[frozenset[str]] = frozenset(
    {"format", "name", "class", "model", "obs_len", "net", "training"}
)

# A zoo name becomes a file name (NAME.pt, NAME.json) and a CasADi function name: letters, digits, "_", "."
# and "-", starting with a letter or digit, so that no name is a path ("../x", "/tmp/x"), hidden, "." or "..".
NAME_PATTERN: Final[re.Pattern[str]] = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
# Observed steps a checkpoint may ask for: TrajNet++ observes 9 (3.6 s at 2.5 Hz); 100 steps are 40 s of
# history, beyond any scene's, and the encoder (torch and CasADi) unrolls once per step.
MAX_OBS_LEN: Final[int] = 100
# A manifest or config is a few kB (the shipped manifest 13 kB); refuse to read a huge file into memory.
MAX_DOCUMENT_BYTES: Final[int] = 64 << 20
# A weights file holds the net's tensors (at most 8 bytes an element, float64) plus torch's zip framing.
WEIGHTS_OVERHEAD_BYTES: Final[int] = 1 << 20


def check_name(name: object, what: str = "zoo name") -> str:
    """``name`` if it is a safe zoo name (``NAME_PATTERN``), else PredictorError."""
    if not isinstance(name, str) or NAME_PATTERN.fullmatch(name) is None:
        raise PredictorError(
            f"{what} {short_repr(name)} is not allowed: use 1 to 64 letters, digits, '_', '.' or '-', "
            "starting with a letter or digit"
        )
    return name


def check_sha256(value: object, what: str) -> str:
    """``value`` if it is a sha256 as the zoo records it (64 lowercase hex digits), else PredictorError.

    A missing hash is never "skip the check": every zoo file is verified before it is loaded."""
    if not is_sha256(value):
        raise PredictorError(f"{what} must be a sha256 (64 lowercase hex digits), got {short_repr(value)}")
    return value


def read_capped(path: Path, limit: int, room: str, expected: str | None = None) -> bytes:
    """The bytes of ``path``, read once, or PredictorError naming it when it is not a regular file or holds
    more than ``limit`` bytes (refused before they are read; ``room`` ends the message: "a ... may have"),
    CheckpointMismatch for such a file where its sha256 is ``expected``, as a file the cap lets by is."""
    if path.exists() and not path.is_file():  # a directory or a FIFO (reading one would block forever)
        raise PredictorError(f"{path}: not a regular file")
    with path.open("rb") as handle:  # a missing file: FileNotFoundError, as before
        size = os.fstat(handle.fileno()).st_size
        data = handle.read(limit + 1) if size <= limit else b""  # + 1: a file that grew since fstat
    size = max(size, len(data))
    if size > limit:
        # A zoo's file fitted its cap when it was added: one over it was replaced, which the size alone did
        # not say, nor how to mend it. Hashed in blocks, as before the cap was checked first: never held.
        if expected is not None and (found := sha256_file(path)) != expected:
            raise CheckpointMismatch(path, expected, found)
        raise PredictorError(f"{path}: {size} bytes, more than the {limit} {room}")
    return data


def node_kind(path: Path) -> str:
    """What stands at ``path`` where a regular file was expected, in words."""
    if path.is_symlink() and not path.exists():
        return "a symbolic link to nothing"
    if path.is_dir():
        return "a directory"
    return "a FIFO" if path.is_fifo() else "a device or socket"


def read_document(path: Path, document_format: str, what: str) -> dict[str, Any]:
    """A JSON object whose ``"format"`` is ``document_format``, or PredictorError naming ``path``."""
    return parse_document(
        path, read_capped(path, MAX_DOCUMENT_BYTES, f"a {what} may have"), document_format, what
    )


def parse_document(path: Path, data: bytes, document_format: str, what: str) -> dict[str, Any]:
    """``read_document`` of the bytes ``data`` read from ``path``."""
    try:
        document = json.loads(data.decode("utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKey as exc:
        raise PredictorError(f"{path}: {exc}") from None
    except UnicodeDecodeError:
        raise PredictorError(f"{path}: not valid JSON (not UTF-8 text)") from None
    except ValueError as exc:  # JSONDecodeError, or an integer literal of more than 4300 digits
        raise PredictorError(f"{path}: not valid JSON ({exc})") from None
    except RecursionError:
        raise PredictorError(f"{path}: not valid JSON (nested too deeply)") from None
    if not isinstance(document, dict) or document.get("format") != document_format:
        raise PredictorError(f'{path}: not a {what} (expected "format": "{document_format}")')
    return document


# ----------------------------------------------------------------------------------------- checkpoint pair
def save_checkpoint(
    net: torch.nn.Module,
    *,
    model: str,
    name: str,
    out_dir: str | Path,
    obs_len: int,
    extra: dict | None = None,
) -> tuple[Path, Path]:
    """Write ``out_dir/NAME.pt`` (float32 state_dict) and ``out_dir/NAME.json``; returns both paths.

    ``model`` is a registered model kind (``predictors.models``) whose net class ``net`` is."""
    import torch

    from predictors.models import model_kind

    check_name(name, "checkpoint name")  # NAME becomes the files' names
    kind = model_kind(model)
    if not isinstance(net, kind.net_class):
        raise PredictorError(f"model {model!r} is a {kind.net_class.__name__}, got a {type(net).__name__}")
    net_config = kind.config_dict(getattr(net, "config", None))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    weights = out_dir / f"{name}.pt"
    config = out_dir / f"{name}.json"
    state = {k: v.detach().to("cpu", torch.float32).clone() for k, v in net.state_dict().items()}
    torch.save(state, weights)
    document = {
        "format": CONFIG_FORMAT,
        "name": name,
        "class": kind.predictor_class_name,  # informational: the kind decides
        "model": kind.name,
        "obs_len": obs_len,
        "net": net_config,
        **(extra or {}),
    }
    config.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    return weights, config


def _legacy_model(document: dict[str, Any], config: Path) -> str:
    """The model kind of a config written before ``"model"`` existed: its predictor class and pooling."""
    cls_name = document.get("class")
    if cls_name == "SocialGANPredictor":
        return "social_gan"
    if cls_name == "SocialLSTMPredictor":
        net = document.get("net")
        return "vanilla_lstm" if isinstance(net, dict) and net.get("pooling") == "none" else "social_lstm"
    raise PredictorError(f'{config}: "model" is missing; `crowdmpc train` writes it')


class CheckedPair(NamedTuple):
    """A checkpoint pair as ``read_checkpoint`` read it, each file once: its predictor and the bytes it was
    built and loaded from, for a caller that keeps them (`zoo add` copies them into the zoo)."""

    predictor: LearnedPredictor
    weights: bytes  # the .pt's bytes, loaded (their sha256: predictor.weights_sha256)
    config: bytes  # the .json's bytes, parsed


def load_checkpoint(
    weights: str | Path,
    config: str | Path | None = None,
    *,
    name: str | None = None,
    expected_sha256: str | None = None,
    expected_config_sha256: str | None = None,
) -> LearnedPredictor:
    """The predictor of a checkpoint pair: ``read_checkpoint``'s, without the files' bytes."""
    return read_checkpoint(
        weights,
        config,
        name=name,
        expected_sha256=expected_sha256,
        expected_config_sha256=expected_config_sha256,
    ).predictor


def read_checkpoint(
    weights: str | Path,
    config: str | Path | None = None,
    *,
    name: str | None = None,
    expected_sha256: str | None = None,
    expected_config_sha256: str | None = None,
    check_config: Callable[[dict[str, Any]], None] | None = None,
) -> CheckedPair:
    """The predictor of a checkpoint pair (``config`` defaults to ``weights`` with ``.json``), with the bytes
    of each file it was made from. ``check_config``: called with the parsed config before its model kind is
    looked up, for a caller's own refusal of the bytes that then load (`zoo add --shipped`'s kinds).

    Everything is checked before it is used, each failure a PredictorError naming the file: each file's
    sha256 (when expected, as the zoo always does) on the bytes then used, the config's first, the model
    kind (registered, never imported on the file's word), the config's types and ranges before any net is
    built (its size counted on the meta device), the weights' size before they are read, then that they are
    a state_dict of finite float tensors of the net's shapes.
    """
    weights = Path(weights)
    config = Path(config) if config is not None else weights.with_suffix(".json")
    for path, expected in ((weights, expected_sha256), (config, expected_config_sha256)):
        _check_file(path, expected)
    # Each file is read once, and the bytes hashed are the bytes used: hashed, then read again, a file
    # replaced between the reads (`zoo add --replace`) built or loaded other bytes than were checked.
    what = "crowdmpc predictor config"
    data = read_capped(config, MAX_DOCUMENT_BYTES, f"a {what} may have", expected_config_sha256)
    _check_bytes(config, data, expected_config_sha256)
    document = parse_document(config, data, CONFIG_FORMAT, what)
    if check_config is not None:
        check_config(document)
    kind = _config_kind(document, config)
    own_name = document.get("name", weights.stem)
    if not isinstance(own_name, str):
        raise PredictorError(f'{config}: "name" must be a string, got {short_repr(own_name)}')
    obs_len = document.get("obs_len", OBS_LEN)
    if isinstance(obs_len, bool) or not isinstance(obs_len, int):
        raise PredictorError(f'{config}: "obs_len" must be an integer, got {short_repr(obs_len)}')
    if not 2 <= obs_len <= MAX_OBS_LEN:
        raise PredictorError(f'{config}: "obs_len" must be in 2..{MAX_OBS_LEN}, got {obs_len}')
    net, weights_data, sha256 = _loaded_net(kind, document, weights, config, expected_sha256)
    try:
        predictor = kind.predictor(net, name=name or own_name, obs_len=obs_len)
    except PredictorError as exc:
        raise PredictorError(f"{config}: {exc}") from None
    # what a run records it planned with: the zoo's manifest, read again, may name weights put in since
    predictor.weights_sha256 = sha256
    return CheckedPair(predictor, weights_data, data)


def _check_file(path: Path, expected: str | None) -> None:
    """PredictorError unless ``path`` is a regular file and ``expected`` (when given) a sha256."""
    if not path.exists():
        raise PredictorError(f"checkpoint file {path} does not exist")
    if not path.is_file():
        raise PredictorError(f"checkpoint file {path} is not a regular file")
    if expected is not None:
        check_sha256(expected, f"the expected sha256 of {path}")


def _check_bytes(path: Path, data: bytes, expected: str | None) -> str:
    """The sha256 of ``data``, read from ``path``; CheckpointMismatch unless it is ``expected`` (if given)."""
    found = hashlib.sha256(data).hexdigest()
    if expected is not None and found != expected:
        raise CheckpointMismatch(path, expected, found)
    return found


def _config_kind(document: dict, config: Path) -> ModelKind:
    """The registered model kind the config ``document`` names, agreeing with its informational "class"."""
    from predictors.models import model_kind

    cls_name = document.get("class")
    if cls_name is not None and (not isinstance(cls_name, str) or cls_name not in PREDICTOR_CLASS_NAMES):
        raise PredictorError(
            f"{config}: unknown predictor class {short_repr(cls_name)}; expected one of "
            f'{list(PREDICTOR_CLASS_NAMES)} (or no "class": it is informational)'
        )
    model = document["model"] if "model" in document else _legacy_model(document, config)
    try:
        kind = model_kind(model)  # a registered kind only: a file never makes us import a module
    except PredictorError as exc:
        raise PredictorError(f'{config}: "model": {exc}') from None
    if cls_name is not None and (cls_name == "SocialGANPredictor") != kind.adversarial:
        raise PredictorError(f'{config}: "model" {kind.name!r} does not go with "class" {cls_name!r}')
    return kind


def _loaded_net(
    kind: ModelKind, document: dict, weights: Path, config: Path, expected: str | None
) -> tuple[torch.nn.Module, bytes, str]:
    """The net of ``document``'s "net", built and bounded before any memory is taken, with the weights of
    ``weights`` once their size, their sha256 (``expected``, when given) and every tensor are checked; and
    the bytes they were loaded from, and their sha256."""
    import torch

    try:
        # The initial weights, replaced by the checkpoint's below, are drawn from a fork of torch's global
        # generator: a caller who seeded torch gets the same random numbers after a load as without it.
        with torch.random.fork_rng(devices=[]):
            net = kind.build_net(document.get("net", {}))  # validated, and bounded before memory is taken
    except PredictorError as exc:
        raise PredictorError(f'{config}: "net": {exc}') from None
    expected_state = net.state_dict()
    limit = 8 * sum(t.numel() for t in expected_state.values()) + WEIGHTS_OVERHEAD_BYTES
    data = read_capped(weights, limit, f"a state_dict of the net of {config} can take", expected)
    sha256 = _check_bytes(weights, data, expected)
    try:
        state = load_tensors(io.BytesIO(data))
    except Exception:  # whatever a corrupt or hostile file makes torch raise, the file is at fault
        # torch's own message suggests weights_only=False, which a checkpoint must never need
        raise PredictorError(
            f"{weights}: not a state_dict of tensors as `crowdmpc train` writes (truncated, or not a "
            "torch file, or a pickled object, which is never loaded)"
        ) from None
    check_state_dict(state, expected_state, weights, config)
    try:
        net.load_state_dict(state, strict=True)
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:  # not expected after the checks above
        raise PredictorError(f"{weights}: weights do not fit the net of {config}: {exc}") from None
    return net, data, sha256


def load_tensors(path: Path | BinaryIO) -> Any:
    """``torch.load(path, weights_only=True)`` onto the CPU, never a pickled object, and without torch's
    advice on a pickle's protocol, a warning of two lines that came before the caller's one-line refusal of
    such a file (`zoo add`, `train --resume`)."""
    import torch

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return torch.load(path, map_location="cpu", weights_only=True)


def check_state_dict(state: object, expected: dict[str, Any], weights: Path, config: Path) -> None:
    """PredictorError (one line, naming ``weights``) unless ``state`` holds exactly the tensors of
    ``expected`` (a net's ``state_dict``), each of its shape, floating point and finite."""
    import torch

    if not isinstance(state, dict):
        raise PredictorError(f"{weights}: not a state_dict (a dict of tensors), but a {type(state).__name__}")
    for key, value in state.items():
        if not isinstance(key, str):
            raise PredictorError(f"{weights}: a state_dict key is {short_repr(key)}, not a string")
        if not isinstance(value, torch.Tensor) or value.layout != torch.strided or value.is_quantized:
            raise PredictorError(
                f"{weights}: {short_repr(key)} is a {type(value).__name__}, not a dense tensor"
            )
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if missing or unexpected:
        raise PredictorError(
            f"{weights}: weights do not fit the net of {config}: missing {short_repr(missing, 120)}, "
            f"unexpected {short_repr(unexpected, 120)}"
        )
    for key, value in state.items():
        want = tuple(expected[key].shape)
        if tuple(value.shape) != want:
            raise PredictorError(
                f"{weights}: tensor {key!r} has shape {tuple(value.shape)}, the net of {config} needs {want}"
            )
        if value.dtype not in (torch.float16, torch.bfloat16, torch.float32, torch.float64):
            # float8 passes is_floating_point but has no isfinite; a meta tensor holds no values at all
            raise PredictorError(
                f"{weights}: tensor {key!r} is {value.dtype}, not floating point of 16, 32 or 64 bits"
            )
        if value.device.type != "cpu":
            raise PredictorError(f"{weights}: tensor {key!r} is on device {value.device.type!r}, not the cpu")
        if not bool(torch.isfinite(value).all()):
            raise PredictorError(f"{weights}: tensor {key!r} holds NaN or infinite values")
