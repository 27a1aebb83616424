"""``crowdmpc simulate --help``'s examples and explanation, kept apart from the command (simulate.py)."""

from __future__ import annotations

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
