"""The exported CasADi predictors against the hand-written twins they replaced, side by side in one run.

For every model (zoo names): export time (to_casadi + encoder, fresh predictor; the process's first export
is a throwaway copy's, untimed, so that no model is charged for the exporter's first use), parity with
torch (values and Jacobians with respect to the robots' plan), the IBR prediction time per call (the
prediction function evaluated numerically through mpc/fastcall.py's buffers, as the loop does several times
a control step) and the coupled-NLP control step (CMPC with the predictor inside the NLP, one circle
episode). Models of the Social-LSTM family are also run through the hand-written twin kept in
``tests/predictors/handwritten`` (the cross-check: its value error is against the export, and its Jacobian
is not checked, "-"), and the ratio exported / hand-written is printed: the target is <= 1.5.
``--no-closed-loop`` leaves the coupled-NLP step out ("-").

    nice -n 5 .venv/bin/python benchmarks/export.py
    nice -n 5 .venv/bin/python benchmarks/export.py --models social_lstm_soft_eth --humans 7 --calls 500
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the cross-check twin lives in tests/

from crowdsim.env import CrowdEnv  # noqa: E402
from mpc.fastcall import BufferedFunction  # noqa: E402
from pipelines.loop.controllers import ControllerSpec  # noqa: E402
from pipelines.loop.mpc import MPCController  # noqa: E402
from predictors.export.parity import check_parity, crossing_scene  # noqa: E402
from predictors.learned import LearnedPredictor  # noqa: E402
from predictors.registry import load_predictor  # noqa: E402
from predictors.text_table import counted  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import count_in, figure, predicted_humans, run_main  # noqa: E402


def handwritten(predictor: LearnedPredictor):
    """The hand-written twin's prediction builder for a Social-LSTM-family net, or None for other nets."""
    from predictors.nets.social_lstm import SocialLSTM
    from tests.predictors.handwritten.twin import SocialLSTMTwin

    if not isinstance(predictor.net, SocialLSTM):
        return None
    weights = {k: v.detach().numpy().astype(np.float64) for k, v in predictor.net.state_dict().items()}
    twin = SocialLSTMTwin(weights, predictor.config)
    return lambda n_h, n_r, horizon: twin.prediction(predictor.name, n_h, n_r, horizon)


def per_call_ms(function, context: np.ndarray, plan: np.ndarray, calls: int) -> float:
    """The median ms of one call of ``function`` as the IBR loop makes it: through mpc/fastcall.py's buffers
    (``MPCController._twin``), not CasADi's own call, whose argument conversions cost a quarter more."""
    call = BufferedFunction(function)
    call(context, plan)
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        call(context, plan)
        times.append(time.perf_counter() - start)
    return float(np.median(times) * 1e3)


def coupled_step_ms(name: str, n_humans: int, build=None, seed: int = 0) -> float:
    """Median control step of CMPC with the prediction inside the NLP over one circle episode."""
    controller = MPCController(ControllerSpec("cmpc", name, coupling="nlp"), distributed=False)
    if build is not None:
        controller.model.to_casadi = build  # the hand-written twin instead of the exported function
    env = CrowdEnv()
    obs = env.reset(seed, "circle", n_humans, 3)
    controller.reset(obs)
    times = []
    done = False
    while not done:
        output = controller.act(obs)
        times.append(output.solve_time_s)
        obs, done, _ = env.step(output.accelerations)
    controller.close()
    return float(np.median(times) * 1e3)


_warmed_up = False  # whether this process has exported once, untimed (measure)


def measure(name: str, n_humans: int, calls: int, closed_loop: bool) -> list[dict[str, Any]]:
    global _warmed_up
    predictor = load_predictor(name)
    if not isinstance(predictor, LearnedPredictor):
        raise SystemExit(f"{name} is not a learned predictor")
    if not _warmed_up:
        # A process's first export pays for its first use of the exporter (lazy imports, the first symbolic
        # runs), which was charged to the run's first model: vanilla_lstm_eth 2.13 s first, 0.66 s after.
        load_predictor(name).to_casadi(n_humans, 3, 4)  # a throwaway copy: the timed one starts fresh
        _warmed_up = True
    start = time.perf_counter()  # export: symbolic runs, the first export's parity check, the encoder
    function = predictor.to_casadi(n_humans, 3, 4)
    history, mask, humans, plan = crossing_scene(n_humans, 3, 4, predictor.obs_len)
    context = predictor.encode(history, mask, humans)
    export_s = time.perf_counter() - start
    parity = check_parity(predictor, n_humans, 3, 4)
    rows = [
        {
            "model": name,
            "twin": "exported",
            "export_s": export_s,
            "value_err": parity.value_error,
            "jac_err": parity.jacobian_error,
            "ibr_ms": per_call_ms(function, context, plan.ravel(), calls),
            "nlp_ms": coupled_step_ms(name, n_humans) if closed_loop else float("nan"),
        }
    ]
    build = handwritten(predictor)
    if build is not None:
        start = time.perf_counter()
        twin = build(n_humans, 3, 4)
        twin_s = time.perf_counter() - start
        value = np.asarray(twin(context, plan.ravel())).ravel()
        rows.append(
            {
                "model": name,
                "twin": "hand-written",
                "export_s": twin_s,
                "value_err": float(np.abs(value - np.asarray(function(context, plan.ravel())).ravel()).max()),
                "jac_err": float("nan"),
                "ibr_ms": per_call_ms(twin, context, plan.ravel(), calls),
                "nlp_ms": coupled_step_ms(name, n_humans, build) if closed_loop else float("nan"),
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--models", help="zoo names, comma-separated (default: every model of the shipped and the user zoo)"
    )
    parser.add_argument(
        "--humans", type=predicted_humans, default=7, help="at least 1: the twin predicts the humans"
    )
    parser.add_argument("--calls", type=count_in("calls", 1), default=300)
    parser.add_argument("--no-closed-loop", action="store_true", help="skip the coupled-NLP episodes")
    args = parser.parse_args()
    from predictors.models import model_names
    from predictors.zoo import read_manifest, zoo_names

    available = set(zoo_names())
    # every model the zoos hold by default: a fixed list of six left social_lstm_synth and users' models out
    wanted = [name for name in args.models.split(",") if name] if args.models else sorted(available)
    unknown = [name for name in wanted if name not in available]
    if unknown:  # a typo ran nothing, printed "(not in the zoo)" and exited 0
        parser.error(
            f"--models: {', '.join(unknown)} not in the zoo; choose from {', '.join(sorted(available))}"
        )
    entries, kinds = read_manifest(), set(model_names())
    load = os.getloadavg()[0]
    print(
        f"load average {load:.2f} on {os.cpu_count()} cores; {counted(args.humans, 'human')}, 3 robots, H=4"
    )
    columns = ("export s", "value err", "jac err", "IBR ms", "NLP ms")
    widths = (9, 10, 10, 8, 8)
    print(f"{'model':22} {'twin':13} " + " ".join(f"{c:>{w}}" for c, w in zip(columns, widths, strict=True)))
    for name in wanted:
        model = entries[name].model
        if model not in kinds:  # a user's plugin net: it loads once its plugin is registered
            print(f"{name:22} (a plugin's model: CROWDMPC_PLUGINS={model} measures it)")
            continue
        rows = measure(name, args.humans, args.calls, not args.no_closed_loop)
        for row in rows:
            print(
                f"{row['model']:22} {row['twin']:13} {row['export_s']:9.3f} {row['value_err']:10.1e} "
                f"{figure(row['jac_err'], '10.1e')} {row['ibr_ms']:8.3f} {figure(row['nlp_ms'], '8.2f')}"
            )
        if len(rows) == 2:
            print(
                f"{'':22} {'ratio':13} {'':9} {'':10} {'':10} {rows[0]['ibr_ms'] / rows[1]['ibr_ms']:8.2f} "
                f"{figure(rows[0]['nlp_ms'] / rows[1]['nlp_ms'], '8.2f')}"
            )


if __name__ == "__main__":
    raise SystemExit(run_main(main))
