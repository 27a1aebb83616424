"""``crowdmpc calibrate --help``'s examples and explanation, kept apart from the command (calibrate.py)."""

from __future__ import annotations

EPILOG = """examples:
  crowdmpc calibrate --predictor social_lstm_eth --source closed-loop --alpha 0.5,0.2,0.1,0.05,0.01
  crowdmpc calibrate --predictor constant_velocity --source real --alpha 0.1 --holdout
  crowdmpc calibrate --predictor social_lstm_eth --source closed-loop --alpha 0.1 --episodes 20 --dry-run
  crowdmpc calibrate --predictor social_lstm_eth --source closed-loop --alpha 0.1 --sensor-range 3 --holdout

Each alpha gives one block in the user zoo's calibrations.json ($CROWDMPC_ZOO; the shipped zoo's blocks are
read-only defaults): the (1 - alpha) split-conformal quantile of the predictor's displacement error at each
horizon step k = 1..H, used as the margin m_k of `--margins conformal:ALPHA[:SOURCE]` (simulate, sweep).
Sources: real (the prepared ETH/hotel validation scenes), closed-loop (CMPC episodes with no margins on seeds
from 1,000,000 on, disjoint from every evaluation seed; only humans within --near m of a robot are scored;
with --sensor-range the robots see the humans within that range, tracked since they came into view
(--no-sensor-tracks: their track lengths not given), and the block records the sensor: it is stored beside the
one of robots that see everyone, and runs behind that sensor plan with it). A closed-loop block also holds the
quantiles of each motion class (new, standing, slow, walking), the margins of `--margins
conformal-motion:ALPHA`, and per class those of the distance shortfall (how much closer a human came to a
robot than predicted), the margins of `--margins conformal-shortfall:ALPHA`. A block without the per-class
margins (too few samples in a class) is not stored over one that has them. --holdout measures coverage on data
the calibration did not see: the test scenes (real) or as many further episodes (closed-loop; per motion class
too). The blocks are stored after those episodes; when they plan with a block this run makes
(--holdout-margins conformal:ALPHA with ALPHA one of --alpha), it is stored before them and taken back if the
run stops, by the next calibrate after a kill -9. A note says when the episodes' seeds are ones simulate and
sweep evaluate on, or the real scenes ones the model was trained on, when margins pass the 5 m a plan can
keep, and when a block replaces one made otherwise (another --controller, other seeds or episodes); a run
planning with a block made with another controller says so too. `crowdmpc zoo calibrations`
lists each block's controller and episodes.
"""


def option_helps(default: dict) -> dict[str, str]:
    """The help of options whose line would not fit calibrate.py's register, each closed-loop one stating
    ``default``'s value for it (the schema's, not a literal)."""
    return {
        "episodes": f"closed-loop episodes to run (default {default['episodes']})",
        "seed": f"first closed-loop episode's seed (default {default['seed']})",
        "controller": f"closed-loop robots' controller (default {default['controller']})",
        "profile": f"closed-loop simulation conventions (default {default['profile']})",
        "visibility": f"closed-loop: robots seen by the humans' ORCA (default {default['visibility']})",
        "near": f"closed-loop: score only the humans within M m of a robot (default {default['near']})",
        "json": "also write the blocks and coverage as JSON (-: standard output)",
        "no-progress": "no progress bar (drawn on a terminal only)",
    }
