"""``crowdmpc export``: a predictor's symbolic twin as a saved CasADi Function (``Function.save``)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS
from mpc.sizes import MAX_HORIZON  # the MPC's: the CasADi function unrolls H recursive steps
from pipelines.commands import check_outside_the_zoos, check_writable, replace_file
from pipelines.commands.output_paths import file_output_arg
from pipelines.errors import PipelineError, print_note
from predictors.text_table import counted

if TYPE_CHECKING:
    from predictors.manifest import ZooEntry

EPILOG = """examples:
  crowdmpc export social_lstm_soft_eth --out runs/social_lstm_soft_eth.casadi --humans 7 --robots 3 \\
      --horizon 4
  python -c "import casadi; f = casadi.Function.load('runs/social_lstm_soft_eth.casadi'); print(f)"

The function is built for fixed sizes and does recursive coupled prediction over the horizon:
  input  0 "context"        (context_size, 1)  predictor.encode(history, mask, humans): the observed past
                                               encoded numerically (LSTM states after the observed steps,
                                               current positions, the humans' first predicted step, who is
                                               present); agents ordered humans, then robots
  input  1 "robots_future"  (H*M*2, 1)         the robots' planned positions at t+1..t+H, (H, M, 2) row-major
  output 0 "humans_future"  (H*N_h*2, 1)       the humans' predicted positions at t+1..t+H,
                                               (H, N_h, 2) row-major
At every step the humans' predictions are fed back and the robots' positions come from the plan, so the
output depends on the plan (for social pooling, through the neighbours' positions and hidden states).
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "export",
        help="save a predictor's CasADi function (recursive coupled prediction) to a file",
        description="Build predictor NAME's CasADi twin for fixed numbers of humans, robots and horizon "
        "steps "
        "and save it with casadi.Function.save.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("name", help="registered predictor or model-zoo name")
    parser.add_argument(
        "--out", required=True, type=file_output_arg, help="file to write the CasADi function to (.casadi)"
    )
    parser.add_argument(
        "--humans", type=int, default=7, help=f"number of humans N_h, 1..{MAX_HUMANS} (default 7)"
    )
    parser.add_argument(
        "--robots", type=int, default=3, help=f"number of robots M, 0..{MAX_ROBOTS} (default 3)"
    )
    parser.add_argument(
        "--horizon", type=int, default=4, help=f"prediction horizon H, 1..{MAX_HORIZON} (default 4, Table I)"
    )
    parser.set_defaults(func=run)


def _parity(predictor, args: argparse.Namespace):
    """The exported function against torch at the size written (None for a predictor without a net); a
    difference beyond the tolerance is an error, and nothing is written."""
    from predictors.export.parity import require_parity
    from predictors.learned import LearnedPredictor

    if not isinstance(predictor, LearnedPredictor):
        return None
    return require_parity(predictor, args.humans, args.robots, args.horizon)


def _notes(predictor, args: argparse.Namespace, entry: ZooEntry | None) -> list[str]:
    """What the saved function is that its printout would not say: a horizon past what the net was trained
    to predict (its later steps extrapolate, as ``simulate`` notes for the MPC), a generator's zero noise
    (the function is one deterministic future of many); a plugin net whose module changed since training is
    said before the load (``run``). ``entry``: the zoo entry ``predictor`` was loaded from (None: none)."""
    from pipelines.commands.simulate_checks import extrapolated_steps
    from predictors.base import DT
    from predictors.registry import entry_prediction_length
    from predictors.social_lstm_predictors import SocialGANPredictor

    notes = []
    trained = None if entry is None else entry_prediction_length(entry)
    if trained is not None and args.horizon > trained:
        notes.append(
            f"note: --horizon {args.horizon} is past the {trained} steps ({trained * DT:g} s) {args.name!r} "
            f"was trained to predict: the function's {extrapolated_steps(trained, args.horizon)}"
        )
    if isinstance(predictor, SocialGANPredictor):
        notes.append(
            f"note: {args.name!r} is a generator: the function is its zero-noise future, as the MPC plans on "
            "it; its sampled futures (SocialGANPredictor.sample) stay in torch"
        )
    return notes


def _check_replaces_an_export(out: Path) -> None:
    """An existing file is replaced only if it is empty or a CasADi function file (an earlier export): a
    mistyped --out must not overwrite a README, a data file or a recording, as --json and --plot do not."""
    if not out.is_file() or out.stat().st_size == 0:
        return
    import casadi as ca

    try:
        ca.Function.load(str(out))  # its serialization header is checked first: a foreign file fails at once
    except RuntimeError:
        raise PipelineError(
            f"--out {out}: the file exists and is not a CasADi function file; crowdmpc does not overwrite it "
            "(remove it or name another file)"
        ) from None


def _save(function, out: Path) -> None:
    """``function`` saved to a file beside ``out``, loaded back and compared, then renamed over ``out``.

    CasADi's ``Function.save`` ignores write errors (a full disk, ``ulimit -f``) and writes in place, so a
    plain save reported success over a truncated file and destroyed the earlier export at ``out``.
    """
    import casadi as ca

    def save_and_check(name: str) -> None:
        function.save(name)
        try:
            written = ca.Function.load(name).serialize()
        except RuntimeError:  # a cut file does not deserialize
            written = None
        if written != function.serialize():
            raise OSError("the file written does not load back as the function: is the disk full?")

    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        replace_file(out, save_and_check)
    except OSError as exc:
        raise PipelineError(
            f"--out {out}: could not write it ({exc.strerror or exc}); an earlier file there is unchanged"
        ) from None


# agents x horizon steps from which a net's export takes tens of seconds (62 x 5: 9 s with social_lstm_eth)
LONG_EXPORT = 300


def run(args: argparse.Namespace) -> int:
    from predictors.registry import PREDICTORS, load_predictor
    from predictors.zoo import load_located, locate

    # Checked before anything is loaded or built; the agent counts are the simulator's (crowdsim.scenarios).
    if not (
        1 <= args.humans <= MAX_HUMANS and 0 <= args.robots <= MAX_ROBOTS and 1 <= args.horizon <= MAX_HORIZON
    ):
        raise PipelineError(
            f"need --humans in 1..{MAX_HUMANS}, --robots in 0..{MAX_ROBOTS}, --horizon in 1..{MAX_HORIZON}, "
            f"got {args.humans}, {args.robots}, {args.horizon}"
        )
    if args.out.is_dir():
        raise PipelineError(
            f"--out {args.out} is a directory; give the file to write, e.g. {args.name}.casadi"
        )
    try:  # CasADi receives a name with undecodable bytes as "", and saving to that fails after the export
        str(args.out).encode("utf-8")
    except UnicodeEncodeError:
        raise PipelineError(
            f"--out {args.out}: not a UTF-8 file name, which CasADi cannot save to; name another file"
        ) from None
    if args.out.exists() and not args.out.is_file():  # the export replaces the file; never a device node
        raise PipelineError(f"--out {args.out} is not a regular file (a device or a pipe); name a file")
    check_outside_the_zoos(args.out, "--out", "the export")
    check_writable(args.out, "--out")  # before the export, not when CasADi fails to open it afterwards
    _check_replaces_an_export(args.out)
    from pipelines.commands.quick_check_notes import quick_check_note
    from pipelines.commands.simulate_checks import zoo_notes

    # the entry the name loads located once, for the notes and the load: each located apart, the manifest
    # was read three times, and a `zoo add --replace` between had the notes describe other weights
    located = None if args.name in PREDICTORS else locate(args.name)
    entry = None if located is None else located.entry
    # before the load: an edited plugin whose weights no longer fit said why only in simulate
    for note in zoo_notes(args.name, entry):
        print_note(note)
    predictor = load_predictor(args.name) if located is None else load_located(located)
    quick = quick_check_note(args.name, entry)  # once the model loads: not before a refusal of it
    if quick is not None:
        print_note(quick)
    if (args.humans + args.robots) * args.horizon >= LONG_EXPORT and args.name not in PREDICTORS:
        print_note(  # one CasADi call builds and checks it: Ctrl-C and kill -TERM wait for it to return
            f"note: a net's twin for {args.humans + args.robots} agents over {args.horizon} steps takes long "
            "to build and check (here 9 s at 62 agents over 5 steps, 78 s over 20, 8 minutes over 100); an "
            "interrupt waits for CasADi to return"
        )
    start = time.perf_counter()
    function = predictor.to_casadi(args.humans, args.robots, args.horizon)
    seconds = time.perf_counter() - start
    parity = _parity(predictor, args)
    _save(function, args.out)
    size = predictor.context_size(args.humans, args.robots)
    print(
        f"wrote {args.out}: {function.name()} for {counted(args.humans, 'human')}, "
        f"{counted(args.robots, 'robot')}, horizon {args.horizon} (exported in {seconds:.2f} s)"
    )
    if parity is not None:
        from predictors.export.parity import PARITY_TOLERANCE

        if parity.coupling > 0:
            compared = f"largest entry {parity.coupling:.1e}"
        elif args.robots == 0 or args.humans == 0:
            compared = "none: no robots or no humans"
        else:
            compared = "all 0: no prediction depends on the plan, the net pools no neighbours"
        print(
            f"  parity with torch (float64): values {parity.value_error:.1e}, Jacobians with respect to the "
            f"robots' plan {parity.jacobian_error:.1e} (tolerance {PARITY_TOLERANCE:g}; {compared})"
        )
    print(f"  input  context        ({size}, 1)  from {args.name}.encode(history, mask, humans)")
    print(f"  input  robots_future  ({args.horizon * args.robots * 2}, 1)  (H, M, 2) row-major")
    print(f"  output humans_future  ({args.horizon * args.humans * 2}, 1)  (H, N_h, 2) row-major")
    for note in _notes(predictor, args, entry):
        print_note(note)
    return 0
