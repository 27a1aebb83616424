"""``crowdmpc simulate --help``'s examples and explanation, kept apart from the command (simulate.py)."""

from __future__ import annotations

from typing import Final

from pipelines.loop.controllers import COUPLINGS

# What each coupling does (--coupling's help): a coupling added to COUPLINGS without its words here fails
# every --help (KeyError) rather than going unsaid.
_COUPLING_WORDS: Final[dict[str, str]] = {
    "ibr": "iterative best response to the humans' predictions, Algorithms 1 and 2",
    "nlp": "the predictor inside CMPC's joint NLP, coupled prediction and planning (cmpc only)",
    "none": "predict, then plan, the predictor blind to the robots (the ablation of the coupling)",
}

EPILOG = """examples:
  crowdmpc simulate --controller orca --scenario circle --humans 7 --episodes 20 --seed 0
  crowdmpc simulate --controller cmpc --predictor constant_velocity --scenario perpendicular --humans 5 \\
      --episodes 10 --json runs/cmpc.json --plot runs/cmpc.png --record runs/cmpc
  crowdmpc simulate --controller dmpc --no-flocking --coupling ibr --humans 9 --episodes 50
  crowdmpc --plugin my_predictor:MyNet simulate --controller cmpc --predictor my_net_eth --humans 7

  crowdmpc --config docs/examples/demo.toml simulate --humans 5 --record runs/demo-h5 \\
      --plot runs/demo-h5/episode.png    # the file's settings, 5 humans, recorded apart from the demo's

Episode i uses seed S + i. --plot draws the first episode; --record writes one MCAP file per episode.
Every option can also come from a TOML config file (--config FILE, before or after `simulate`; `crowdmpc
config show` prints one with every default) and --set SECTION.KEY=VALUE items (e.g. --set mpc.w_coll=1e6):
defaults < the file < --set < the options given here.
"""


def coupling_help(default: str) -> str:
    """--coupling's help: each coupling and what it does, ``default`` (the config's) marked."""
    return "; ".join(f"{c}{' (default)' if c == default else ''}: {_COUPLING_WORDS[c]}" for c in COUPLINGS)


def margins_help(default: str) -> str:
    """--margins' help, naming ``default``: the margins an unset [controller] margins plans with."""
    paper = "none (the paper, default)" if default == "none" else "none (the paper)"
    return (
        f"allowance for prediction error in the robot-human distance: {paper}, "
        "conformal[:ALPHA[:closed-loop|real]] (a calibration: the shipped predictors' at alpha 0.5, 0.2, "
        "0.1, 0.05, 0.01 come with crowdmpc, others from `crowdmpc calibrate`), conformal-motion[:ALPHA] or "
        "conformal-shortfall[:ALPHA] (a margin per human from its motion class), fixed:M1,..,MH (metres)"
        + ("" if default == "none" else f" (default: {default})")
    )
