"""``crowdmpc simulate``'s refusal of choices its controller would ignore: a value accepted must change the
run, so the ones that could not are one-line errors before any episode."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pipelines.errors import PipelineError
from pipelines.loop.spec import CONTROLLER_KINDS, is_shipped

if TYPE_CHECKING:
    from pipelines.config import RunConfig
    from pipelines.loop.controllers import ControllerSpec

# The shipped MPCs: the controllers that read flocking, record_iterations and [mpc].
MPC_CONTROLLERS = tuple(name for name, kind in CONTROLLER_KINDS.items() if kind.uses_predictor)


def _shown(config: RunConfig, section: str, key: str, value: Any) -> str:
    """A chosen value as an error names it: "--no-flocking", "--set mpc.horizon 10", "run.toml: mpc.horizon
    10" (a switch given as an option says its value by its name)."""
    label = config.label(section, key)
    source = config.source(section, key)
    if isinstance(value, bool):
        return label if source is not None and source.kind == "cli" else f"{label} {str(value).lower()}"
    return f"{label} {value}"


def _refuse(shown: list[str], controller: str, plans_with: str, keys: str) -> None:
    if shown:
        listed = shown[0] if len(shown) == 1 else f"{', '.join(shown[:-1])} and {shown[-1]}"
        raise PipelineError(
            f"{listed}: controller {controller!r} plans with no {plans_with}; {keys} apply to "
            f"the controllers that do ({', '.join(MPC_CONTROLLERS)})"
        )


def check_choices_apply(config: RunConfig, spec: ControllerSpec) -> None:
    """Refuse what ``spec``'s controller would ignore: a predictor, margins or coupling for one that plans
    with no predictor, and flocking, record_iterations or an [mpc] value for ORCA and the straight line,
    which plan with no MPC. Only values the user chose count (``RunConfig.chosen``: a config file shared
    with cmpc may state the defaults); a plugin reads the spec as it sees fit, so only its predictor facts
    are checked. Then ``record_iterations`` without ``record``, which nothing would write."""
    if spec.predictor_name is None:  # ORCA, the straight line, a plugin that predicts nothing
        chosen = config.controller
        _refuse(
            [
                _shown(config, "controller", key, value)
                for key, value, given in (
                    ("predictor", chosen.predictor, config.chosen("controller", "predictor")),
                    ("margins", chosen.margins, spec.margins.mode != "none"),
                    ("coupling", spec.coupling, spec.coupling != "ibr"),
                )
                if given
            ],
            spec.controller,
            "predictor",
            "predictor, margins and coupling",
        )
    if is_shipped(spec.controller) and spec.controller not in MPC_CONTROLLERS:
        mpc = [("controller", key) for key in ("flocking", "record_iterations")]
        mpc += [("mpc", key) for key in config.values["mpc"]]
        _refuse(
            [
                _shown(config, section, key, config.values[section][key])
                for section, key in mpc
                if config.chosen(section, key)
            ],
            spec.controller,
            "MPC",
            "flocking, record_iterations and [mpc]",
        )
    if not config.simulate.sensor_tracks and config.simulate.sensor_range is None:
        raise PipelineError(
            f"{_shown(config, 'simulate', 'sensor_tracks', False)}: track lengths are a sensor's; give "
            "--sensor-range M too (or [simulate] sensor_range)"
        )
    if spec.record_iterations and config.simulate.record is None:
        raise PipelineError(
            f"{config.label('controller', 'record_iterations')}: the iterations are written to the MCAP "
            "recordings; give --record DIR too (or [simulate] record)"
        )
