"""``crowdmpc calibrate``: conformal margins for a predictor, from real scenes or closed-loop episodes."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import TYPE_CHECKING, Any, Final

from pipelines.commands import check_writable, humans_list, path_arg, write_output
from pipelines.commands.calibrate_checks import sensor_range_refusal, wide_margins_notes
from pipelines.commands.calibrate_help import EPILOG, option_helps
from pipelines.commands.calibrate_store import (
    alphas_arg,
    evaluation_seeds_note,
    plans_with_new_blocks,
    storing,
    take_back_before_planning,
    take_back_killed,
    trained_on_notes,
)
from pipelines.commands.standard_output import is_stdout, json_on_stdout, json_path, shown
from pipelines.errors import PipelineError, print_note
from predictors.errors import PredictorError

if TYPE_CHECKING:
    from pipelines.loop.margins import MarginSpec


CLOSED_LOOP_OPTIONS: Final[tuple[str, ...]] = (
    "episodes",
    "humans",
    "seed",
    "controller",
    "profile",
    "visibility",
    "near",
    "sensor_range",
    "sensor_tracks",
)


def _option(name: str) -> str:
    """The option that sets ``name``: ``--sensor-range``, and ``--no-sensor-tracks`` for sensor_tracks."""
    return "--no-sensor-tracks" if name == "sensor_tracks" else f"--{name.replace('_', '-')}"


def _closed_loop_defaults() -> dict[str, Any]:
    """The options only closed-loop calibration takes, with the values ClosedLoopPlan gives them."""
    from pipelines.experiments.calibrate import ClosedLoopPlan

    return {f.name: f.default for f in dataclasses.fields(ClosedLoopPlan) if f.name in CLOSED_LOOP_OPTIONS}


def register(subparsers: argparse._SubParsersAction) -> None:
    from crowdsim.profiles import PROFILES, VISIBILITY
    from predictors.base import SCENE_LENGTH

    p = subparsers.add_parser(
        "calibrate",
        help="conformal prediction margins for a predictor (real scenes or closed-loop episodes)",
        description="Measure a predictor's displacement error per horizon step and store its conformal "
        "quantiles, the safety margins of `--margins conformal`, `conformal-motion` and "
        "`conformal-shortfall`.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--predictor", required=True, help="a registered predictor, a zoo entry or orca_oracle")
    p.add_argument(
        "--source",
        required=True,
        choices=("real", "closed-loop"),
        help="the errors calibrated: real (the prepared ETH/hotel validation scenes) or closed-loop (CMPC "
        "episodes in the simulator)",
    )
    p.add_argument(
        "--alpha",
        type=alphas_arg,
        default=(0.1,),
        metavar="A[,A..]",
        help="miscoverage levels in (0, 1), one block each: margins that cover 1 - A of the errors (default "
        "0.1)",
    )
    p.add_argument(
        "--horizon",
        type=int,
        default=4,
        help=f"steps calibrated (the MPC's H, default 4; closed-loop: the MPC's own; real: at most the "
        f"scenes' {SCENE_LENGTH} less the steps the predictor observes)",
    )
    p.add_argument("--data-dir", type=path_arg, help="raw or prepared data (real; default: $CROWDMPC_DATA)")
    # closed-loop only: None unless typed, so that _check_sources can refuse one given with --source real
    default = _closed_loop_defaults()
    helps = option_helps(default)
    p.add_argument("--episodes", type=int, help=helps["episodes"])
    p.add_argument(
        "--humans",
        type=humans_list,
        metavar="5,6,7",
        help="closed-loop crowd sizes, cycled smallest first whatever their order "
        f"(default {','.join(map(str, default['humans']))})",
    )
    p.add_argument("--seed", type=int, help=helps["seed"])
    p.add_argument("--controller", choices=("cmpc", "dmpc"), help=helps["controller"])
    p.add_argument("--profile", choices=sorted(PROFILES), help=helps["profile"])
    p.add_argument("--visibility", choices=VISIBILITY, help=helps["visibility"])
    p.add_argument("--near", type=float, metavar="M", help=helps["near"])
    p.add_argument(
        "--sensor-range",
        type=float,
        metavar="M",
        help="closed-loop robots behind a sensor of M m, as `simulate --sensor-range` (default: every human "
        "seen)",
    )
    p.add_argument(
        "--no-sensor-tracks",
        dest="sensor_tracks",
        action="store_const",
        const=False,
        help="with --sensor-range: its tracker reports no track lengths, as `simulate --no-sensor-tracks`",
    )
    p.add_argument("--holdout", action="store_true", help="also measure coverage on held-out data")
    p.add_argument(
        "--holdout-margins",
        default="none",
        metavar="SPEC",
        help="closed-loop held-out episodes plan with these margins (e.g. conformal:0.1, once stored); "
        "default none, the calibration's own conditions",
    )
    p.add_argument("--json", type=json_path, metavar="FILE", help=helps["json"])
    p.add_argument("--dry-run", action="store_true", help="measure and print; store nothing")
    # args.progress None: a bar on a terminal only (predictors.progress)
    p.add_argument(
        "--no-progress", dest="progress", action="store_const", const=False, help=helps["no-progress"]
    )
    p.set_defaults(func=run)


def _check_real_horizon(args: argparse.Namespace, predictor: Any) -> None:
    """A real scene holds the predictor's observed steps and then the --horizon steps scored: a longer
    horizon is refused here, not as a fault of the first scene file read."""
    from predictors.base import SCENE_LENGTH

    longest = SCENE_LENGTH - predictor.obs_len
    if args.horizon > longest:
        raise PipelineError(
            f"--horizon {args.horizon}: the real scenes have {SCENE_LENGTH} steps and {args.predictor} "
            f"observes {predictor.obs_len} of them, so --source real calibrates at most {longest} steps "
            "for it"
        )


def _real(args: argparse.Namespace, predictor: Any) -> tuple[list, Any]:
    from predictors.calibration import calibrate_real
    from predictors.data.locate import prepared_dir, protocol_files
    from predictors.real_data import real_errors
    from predictors.registry import loaded_sha256

    _check_real_horizon(args, predictor)
    files = protocol_files(args.data_dir, "paper", progress=args.progress)
    for note in trained_on_notes(args.predictor, files["val"], files["test"] if args.holdout else []):
        print_note(note)
    sha256 = loaded_sha256(predictor)  # of the weights measured: the zoo's entry may be newer by now
    blocks, _ = calibrate_real(
        predictor, files["val"], args.alpha, args.horizon, root=prepared_dir(args.data_dir), sha256=sha256
    )
    holdout = real_errors(predictor, files["test"], args.horizon) if args.holdout else None
    return blocks, holdout


def _plan(args: argparse.Namespace) -> Any:
    from pipelines.config.settings import check_last_seed
    from pipelines.experiments.calibrate import ClosedLoopPlan

    n = args.episodes * (2 if args.holdout else 1)  # --holdout's as many more on the seeds after
    check_last_seed(args.seed, n - 1, f"{n} episodes{' with --holdout' if args.holdout else ''}", "--seed")
    return ClosedLoopPlan(
        predictor=args.predictor,
        episodes=args.episodes,
        seed=args.seed,
        humans=args.humans,
        controller=args.controller,
        profile=args.profile,
        visibility=args.visibility,
        near=args.near,
        sensor_range=args.sensor_range,
        sensor_tracks=args.sensor_tracks,
    )


def _closed_loop(args: argparse.Namespace) -> list:
    from pipelines.experiments.calibrate import closed_loop_errors, errors_sha256
    from predictors.calibration import calibrations_from_errors

    errors, classes, shortfall, details, sha256 = closed_loop_errors(_plan(args), progress=args.progress)
    if errors.shape[0] == 0:
        raise PipelineError(
            f"no human came within --near {args.near:g} m of a robot in {args.episodes} episode(s), so there "
            "is no error to calibrate; raise --near or --episodes"
        )
    if errors.shape[1:] != (args.horizon,):
        raise PipelineError(f"the controller predicts {errors.shape[1:]} steps, --horizon is {args.horizon}")
    return calibrations_from_errors(
        errors,
        args.alpha,
        predictor=args.predictor,
        predictor_sha256=sha256,  # of the weights the episodes loaded
        source="closed-loop",
        data_sha256=errors_sha256(errors, details, classes),
        details=details | {"rows": int(errors.shape[0])},
        classes=classes,
        shortfall=shortfall,
    )


def _closed_loop_holdout(args: argparse.Namespace, sha256: str | None) -> Any:
    """As many further episodes, on the seeds right after the calibration's: crowds it never saw, planning
    with the weights calibrated (``sha256``), else refused."""
    from pipelines.experiments.calibrate import closed_loop_errors
    from pipelines.loop.margins import parse_margins

    plan = _plan(args)
    after = dataclasses.replace(
        plan, seed=plan.seed + plan.episodes, margins=parse_margins(args.holdout_margins)
    )

    def same_weights(loaded: str | None) -> None:  # their coverage would be other weights' (nothing stored)
        if loaded != sha256:
            raise PipelineError(
                f"{args.predictor}'s weights were replaced as calibrate ran (zoo add --replace?): margins of "
                f"sha256 {str(sha256)[:12]}…, held out with {str(loaded)[:12]}…; none stored"
            )

    measured = closed_loop_errors(after, progress=args.progress, check_weights=same_weights)
    return measured.errors, measured.classes, measured.shortfall


def _check_sources(args: argparse.Namespace, holdout_margins: bool) -> None:
    """Refuse an option typed for what this run does not do (the other source's, held-out margins without a
    held-out run): it would be accepted and change nothing."""
    typed = [_option(name) for name in CLOSED_LOOP_OPTIONS if getattr(args, name) is not None]
    if args.source == "real" and typed:
        one = len(typed) == 1
        raise PipelineError(
            f"{', '.join(typed)} {'is' if one else 'are'} for --source closed-loop (its simulated episodes); "
            f"--source real measures recorded scenes: leave {'it' if one else 'them'} out"
        )
    if args.source == "real" and holdout_margins:
        raise PipelineError(
            "--holdout-margins is for --source closed-loop (held-out episodes plan with them); the held-out "
            "real scenes were recorded, nothing plans in them: leave it out"
        )
    if args.source == "closed-loop" and args.data_dir is not None:
        raise PipelineError(
            "--data-dir is for --source real (the recorded scenes it reads); --source closed-loop simulates "
            "its episodes: leave it out"
        )
    if holdout_margins and not args.holdout:
        raise PipelineError(
            f"--holdout-margins {args.holdout_margins}: the held-out episodes of --holdout plan with these "
            "margins, and without --holdout none run: add --holdout or leave it out"
        )


def _check_first(args: argparse.Namespace) -> None:
    """Refuse now what would otherwise fail after the calibration episodes."""
    from pipelines.loop.margins import MarginSpec, parse_margins
    from predictors.calibration_store import calibrations_path, stored_calibrations
    from predictors.registry import checkpoint_sha256

    holdout_margins = parse_margins(args.holdout_margins)  # a typo fails now
    _check_sources(args, holdout_margins != MarginSpec())
    for name, value in _closed_loop_defaults().items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if not 1 <= args.horizon <= 50:
        raise PipelineError(f"--horizon must be in 1..50 steps, got {args.horizon}")
    if not 1 <= args.episodes <= 100_000:
        raise PipelineError(f"--episodes must be in 1..100000, got {args.episodes}")
    check_writable(args.json, "--json", json_only=True)
    if not args.dry_run:  # the user zoo's file (never the shipped zoo's): refused now, not after the episodes
        check_writable(calibrations_path(), "calibrations file", zoo_own=True)
        take_back_killed()  # before anything reads the blocks in force
        stored_calibrations()  # read as storing will: a file calibrate cannot extend fails now
    else:  # stores nothing, but its held-out episodes may plan with the blocks in force: not a killed run's
        take_back_before_planning([holdout_margins])
    if args.source == "closed-loop":
        refused = sensor_range_refusal(args.predictor, args.sensor_range)  # after a killed run's take-back
        if refused is not None:
            raise PipelineError(refused)
        # held-out margins looked up for the weights the zoo holds now; the blocks name those measured
        _check_closed_loop(args, holdout_margins, checkpoint_sha256(args.predictor))
        note = evaluation_seeds_note(args.seed, args.episodes)
        if note is not None:
            print_note(note)


def _check_closed_loop(args: argparse.Namespace, holdout_margins: MarginSpec, sha256: str | None) -> None:
    """The horizon the controller predicts, and the held-out margins resolve (from a block stored already,
    or one this run stores), as the held-out episodes' controller will resolve them."""
    from pipelines.experiments.calibrate import plan_horizon
    from predictors.oracle import ORACLE_PREDICTOR

    horizon = plan_horizon(_plan(args))
    if args.horizon != horizon:
        real = (  # run refuses the oracle on real scenes
            ""
            if args.predictor == ORACLE_PREDICTOR
            else f", or calibrate real scenes at {args.horizon} steps: --source real --horizon {args.horizon}"
        )
        raise PipelineError(
            f"--horizon {args.horizon}: closed-loop calibration measures the {args.controller} MPC's "
            f"predictions, {horizon} steps (its horizon, which calibrate does not change); use --horizon "
            f"{horizon}{real}"
        )
    if not args.holdout or plans_with_new_blocks(args, holdout_margins):
        return
    # as the held-out episodes' controller resolves them
    planned = holdout_margins.behind(args.sensor_range, args.sensor_tracks)
    try:
        planned.resolve(args.predictor, horizon, sha256)
        planned.resolve_classes(args.predictor, horizon, sha256)
    except (PipelineError, PredictorError) as exc:
        raise PipelineError(f"--holdout-margins {args.holdout_margins}: {exc}") from None


def run(args: argparse.Namespace) -> int:
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        return _calibrate(args)


def _calibrate(args: argparse.Namespace) -> int:
    from pipelines.experiments.calibration_report import (
        class_coverage_report,
        coverage_notes,
        format_coverage,
        missing_class_margins,
    )
    from pipelines.plain_json import plain
    from predictors.conformal import coverage
    from predictors.registry import load_predictor

    _check_first(args)
    if args.source == "real":
        from predictors.oracle import ORACLE_PREDICTOR

        if args.predictor == ORACLE_PREDICTOR:
            raise PipelineError(
                "the ORCA oracle knows the simulator, not real people: use --source closed-loop"
            )
        blocks, holdout = _real(args, load_predictor(args.predictor))
    else:
        blocks, holdout = _closed_loop(args), None
    holdout_classes = holdout_shortfall = None
    with storing(blocks, args) as blocks:
        if args.holdout and args.source == "closed-loop":
            sha256 = blocks[0].predictor_sha256  # one predictor's, of the same weights, in every block
            holdout, holdout_classes, holdout_shortfall = _closed_loop_holdout(args, sha256)
    held = holdout is not None and len(holdout) > 0  # none near a robot: no coverage, not an error
    cover = [coverage(holdout, b.quantiles) for b in blocks] if held else None
    n = ", ".join(str(c) for c in blocks[0].n)
    print(f"{args.predictor}: {args.source} calibration, samples per step {n}")
    if args.holdout and args.source == "closed-loop":
        none = "" if held else " (no human came within --near of a robot: no coverage)"
        print(f"held-out: {holdout.shape[0]} samples{none}, planning with margins {args.holdout_margins}")
    elif args.holdout:
        print(f"held-out: {holdout.shape[0]} samples of the prepared test scenes")
    print(format_coverage([b.alpha for b in blocks], [b.quantiles for b in blocks], cover))
    print(coverage_notes([b.alpha for b in blocks], holdout, cover), end="", file=sys.stderr)
    class_cover = class_coverage_report(blocks, holdout, holdout_classes)
    shortfall_cover = class_coverage_report(blocks, holdout_shortfall, holdout_classes, shortfall=True)
    if args.source == "closed-loop":  # a real calibration computes no margins per motion class
        for line in missing_class_margins(blocks):
            print(line)
    for note in wide_margins_notes(blocks):
        print_note(note)
    if args.json is not None:
        payload = {
            "blocks": [b.to_json() for b in blocks],
            "holdout_coverage": cover,
            "holdout_class_coverage": class_cover,
            "holdout_shortfall_coverage": shortfall_cover,
            "holdout_margins": args.holdout_margins if args.holdout else None,
        }
        if holdout is not None:
            payload["holdout_rows"] = int(holdout.shape[0])
        write_output(args.json, json.dumps(plain(payload), indent=1) + "\n", "--json")
        if not is_stdout(args.json):
            print(f"wrote {shown(args.json)}")
    if args.dry_run:  # measured only: the blocks in force are as they were
        print("--dry-run: nothing stored; the calibrations in force are unchanged")
    return 0
