"""What a model kind is (``ModelKind``): a net class that keeps the step contract
(``predictors.nets.contract``), checked when the kind is made, with the config values that make it this kind
and how it is trained. The registry of kinds, shipped ones and plugins, is ``predictors.models``."""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

from predictors.errors import PredictorError, short_repr
from predictors.net_size import MAX_PARAMETERS

if TYPE_CHECKING:
    import torch

    from predictors.learned import LearnedPredictor


@dataclass(frozen=True)
class ModelKind:
    """A trainable predictor: its net class, this kind's config values, and how it is trained."""

    name: str
    net_class: type[torch.nn.Module]
    defaults: Mapping[str, Any] = field(default_factory=dict)
    adversarial: bool = False  # trained as a GAN generator (predictors.training.GANModule)
    source: str = "shipped"  # "shipped", "entry point <dist>", or "plugin"
    # The keys of ``defaults`` that make this kind what it is, each with why. Other defaults are only a
    # starting point; these no override, command-line option or checkpoint may change: a vanilla_lstm with
    # grid pooling would be a Social-LSTM under another name (its zoo name, its cells in the experiments).
    defining: Mapping[str, str] = field(default_factory=dict)
    # Per key, the values a new config of this kind may not take (a test of the value) and why: a
    # social_lstm without pooling is the vanilla_lstm under another name, one with noise the social_gan
    # generator. Checked where a run makes a config (``config``) and where a checkpoint is written
    # (``config_dict``), not where a stored one loads: a model trained before a rule existed keeps loading.
    refused: Mapping[str, tuple[Callable[[Any], bool], str]] = field(default_factory=dict)

    def __post_init__(self):
        check_net_class(self.net_class, self.name)
        undefined = sorted(set(self.defining) - set(self.defaults))
        if undefined:
            raise PredictorError(f"model {self.name!r}: defining keys {undefined} have no value in defaults")
        clashing = sorted(
            key
            for key, (test, _) in self.refused.items()
            if key in self.defaults and test(self.defaults[key])
        )
        if clashing:
            raise PredictorError(f"model {self.name!r}: its defaults take refused values of {clashing}")

    @property
    def config_class(self) -> type:
        return self.net_class.config_class  # type: ignore[attr-defined, no-any-return]

    def has_field(self, name: str) -> bool:
        """Whether this kind's config has a field ``name`` (``train --pooling`` needs ``pooling``)."""
        return any(f.name == name for f in dataclasses.fields(self.config_class))

    @property
    def predictor_class_name(self) -> str:
        """The class ``predictor`` makes, by name: what a checkpoint's informational ``"class"`` says."""
        return "SocialGANPredictor" if self.adversarial else "LearnedPredictor"

    def config_dict(self, config: Any) -> dict[str, Any]:
        """``config`` (a ``config_class`` instance) as the JSON object a checkpoint stores."""
        if not isinstance(config, self.config_class):
            raise PredictorError(
                f"{self.name}: expected a {self.config_class.__name__}, got {type(config).__name__}"
            )
        self.check_defining(config)  # a checkpoint is never written that its loader would refuse
        self.check_new(config)
        to_dict = getattr(config, "to_dict", None)
        return dict(to_dict()) if callable(to_dict) else dataclasses.asdict(cast(Any, config))

    def config(self, overrides: Mapping[str, Any] | None = None) -> Any:
        """This kind's config: the class defaults, then ``defaults``, then ``overrides``; validated. An
        override may repeat a defining value (a stored config holds them all) but not change it."""
        if overrides is not None and not isinstance(overrides, Mapping):
            return self._config(overrides)  # refused there, in one line
        values = {**self.defaults, **(overrides or {})}
        config = self._config(values)
        from predictors.nets.config_checks import check_annotated_types

        check_annotated_types(self.config_class, values, self.name)  # what the class's own checks let by
        self.check_new(config)
        return config

    def _config(self, values: Mapping[str, Any]) -> Any:
        cls = self.config_class
        if not isinstance(values, Mapping):
            raise PredictorError(f"a {self.name} config must be a JSON object, got {short_repr(values)}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise PredictorError(
                f"unknown {self.name} config keys {short_repr(unknown, 200)}; expected a subset of "
                f"{sorted(known)}"
            )
        from_dict = getattr(cls, "from_dict", None)
        try:
            config = from_dict(dict(values)) if callable(from_dict) else cls(**values)
        except PredictorError:
            raise
        except Exception as exc:  # a plugin's own validation (TypeError, ValueError, an assert ...)
            raise PredictorError(f"{self.name} config: {type(exc).__name__}: {exc}") from None
        # On the built config, not on ``values``: a checkpoint's "net" without the key gets the class's
        # default, which need not be this kind's (SocialLSTMConfig pools on a grid by default).
        self.check_defining(config)
        return config

    def check_new(self, config: Any) -> None:
        """PredictorError naming the key and this kind when ``config`` takes a value ``refused`` for it."""
        for key, (test, why) in self.refused.items():
            value = getattr(config, key, None)
            if test(value):
                raise PredictorError(f"{key} {short_repr(value)} is not a {self.name} ({why})")

    def check_defining(self, config: Any) -> None:
        """PredictorError naming the key and this kind unless ``config`` keeps every defining value."""
        for key, why in self.defining.items():
            found, want = getattr(config, key, None), self.defaults[key]
            if found != want:
                raise PredictorError(
                    f"{key} {short_repr(found)} is not a {self.name}: the kind is defined by {key} {want!r} "
                    f"({why}); choose another model kind"
                )

    def build_net(self, config: Any) -> torch.nn.Module:
        """The net of ``config`` (a ``config_class`` instance, or a dict validated like ``config``).

        Its size is counted on the meta device first: no config can make us allocate more than
        ``MAX_PARAMETERS`` parameters."""
        if isinstance(config, self.config_class):
            self.check_defining(config)  # a dict is checked by _config
        else:
            config = self._config(config)
        probe = self._meta_net(config)
        count = sum(p.numel() for p in probe.parameters())
        if count > MAX_PARAMETERS:
            raise PredictorError(
                f"{self.name}: this config makes a net of {count:,} parameters, more than the "
                f"{MAX_PARAMETERS:,} allowed"
            )
        return self.net_class(config)

    def head_type(self, config: Any) -> object:
        """The ``head_type`` of this kind's net for ``config`` (the contract's "gaussian" or "point"; what
        training loss it takes): the class's own when it names one, else a net's built on the meta device
        (a property of the config, as Social-LSTM's ``head``), allocating nothing."""
        static = inspect.getattr_static(self.net_class, "head_type", None)
        if isinstance(static, str):
            return static
        from predictors.nets.contract import head_type_of

        return head_type_of(self._meta_net(config), f"model {self.name!r}")

    def _meta_net(self, config: Any) -> torch.nn.Module:
        import torch

        try:
            with torch.device("meta"):
                return self.net_class(config)
        except PredictorError:
            raise
        except Exception as exc:  # a plugin's constructor: its fault is the config's or the class's
            raise PredictorError(
                f"{self.name}: building the net failed: {type(exc).__name__}: {exc}"
            ) from None

    def predictor(self, net: torch.nn.Module, *, name: str, obs_len: int) -> LearnedPredictor:
        from predictors.learned import LearnedPredictor
        from predictors.social_lstm_predictors import SocialGANPredictor

        self.check_defining(getattr(net, "config", None))
        cls: type[LearnedPredictor] = SocialGANPredictor if self.adversarial else LearnedPredictor
        return cls(net, name=name, obs_len=obs_len, kind=self.name)


def check_net_class(cls: object, name: str) -> None:
    """PredictorError naming ``name`` unless ``cls`` keeps the step contract (``nets.contract``)."""
    import torch

    where = f"model {name!r}"
    if not (inspect.isclass(cls) and issubclass(cls, torch.nn.Module)):
        raise PredictorError(f"{where}: {short_repr(cls)} is not a torch.nn.Module subclass")
    config_class = getattr(cls, "config_class", None)
    if not (inspect.isclass(config_class) and dataclasses.is_dataclass(config_class)):
        raise PredictorError(f"{where}: {cls.__name__}.config_class must be a dataclass of hyper-parameters")
    for method in ("encode", "decode_step"):
        if not callable(getattr(cls, method, None)):
            raise PredictorError(
                f"{where}: {cls.__name__} has no {method}() (see predictors/nets/contract.py)"
            )
    if not hasattr(cls, "head_type"):
        raise PredictorError(f'{where}: {cls.__name__} has no "head_type" ("gaussian" or "point")')
