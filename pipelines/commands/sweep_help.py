"""``crowdmpc sweep --help``'s examples and explanation, kept apart from the command (commands/sweep.py)."""

from __future__ import annotations

EPILOG = """examples:
  crowdmpc sweep --experiment table2 --episodes-per-cell 100 --workers 2 --out runs/table2
  crowdmpc sweep --experiment table2 --predictor constant_velocity --humans 7 --episodes-per-cell 4 \\
      --out /tmp/sw
  crowdmpc sweep --experiment predictors --episodes-per-cell 100 --record failures --out runs/predictors
  crowdmpc --plugin my_predictor:MyNet sweep --experiment predictors \\
      --predictors constant_velocity,social_lstm_eth,my_net_eth --episodes-per-cell 20 --out runs/swap
  crowdmpc --plugin my_controller:MyCtl sweep --experiment controllers \\
      --controllers cmpc,orca,my_controller:MyCtl --episodes-per-cell 20 --out runs/controllers
  crowdmpc sweep --experiment table2 --margins conformal:0.1 --profile paper --out runs/table2-cp
  crowdmpc sweep --experiment table3 --reuse runs/table2 --episodes-per-cell 100 --out runs/table3
  crowdmpc sweep --experiment table3 --workers 64 --ray-address ray://head:10001 --out /shared/runs/table3
  crowdmpc --config run.toml --set mpc.w_coll=1e6 sweep --experiment table2 --out runs/table2-wcoll
  crowdmpc sweep --experiment sensing --episodes-per-cell 100 --out runs/sensing
  crowdmpc sweep --experiment table2 --vary mpc.d_min=0.8,0.9 --vary controller.margins=none,conformal:0.1 \\
      --humans 7 --out runs/t2-grid

Experiments: table2 (CMPC vs DMPC), table3 (CMPC with/without flocking), both x 5-9 humans with the paper's
figures beside ours; predictors (CMPC at 7 humans with each predictor and an ORCA-ground-truth oracle; by
default the shipped models, --predictors for any list of registered and zoo names, a user zoo's included);
coupling (CMPC by iterated best response vs the coupled NLP, exact and first-order, 7 humans); safety (CMPC
without margins and with conformal margins at alpha 0.5 .. 0.01: pooled, per motion class and per motion class
of the distance shortfall, 7 humans); conventions (simulation profile x robot visibility x margins, 7 humans);
baselines (straight and ORCA robots, a quick check); controllers (each controller at 7 humans, by default
cmpc, dmpc, orca and straight; --controllers for any list, controller plugins included); sensing (CMPC given
every human vs behind a sensor of 4, 3 and 2 m with track lengths, and 3 m without, 7 humans).
--margins applies to every method that plans with a predictor (of controllers: cmpc and dmpc; orca and
straight plan with none, and run without margins); baselines, conventions and safety fix their methods'
margins and refuse it. --profile and --visibility apply to every method; conventions fixes them and refuses
both. --sensor-range puts every method's controller behind a sensor (all but the sensing experiment);
--crowd eth|hotel|eth_test|hotel_test replays BIWI's pedestrians as every cell's humans (crowdsim/replay.py).
Episode i of every cell is the same crowd (circle for even i, perpendicular for odd i, seed --seed + i // 2)
where the cells have the same number of robots and profile: another team or profile draws other humans.
Every option can also come from a TOML config file (--config FILE, before or after `sweep`; its [sweep]
section, `crowdmpc config show` lists every key) and --set SECTION.KEY=VALUE items: defaults < the file <
--set < the options given here. [controller] and [mpc] values that differ from their defaults apply to every
method, and [env] and [env.orca] values (the humans' ORCA, the time limit, the formation, ...) to every cell
over its profile's (each becomes part of the cell keys; e.g. --set env.orca.time_horizon=2); a value the
experiment compares across its methods is refused, as are [world] values (the world facts the controllers
and predictors are built for) and [scenario] humans and name (simulate-only).

Rerunning the same command resumes: episodes already in DIR/episodes.jsonl are not run again (a larger
--episodes-per-cell extends the sweep). --reuse OTHER takes first the episodes sweep OTHER recorded of this
plan's cells (a cell's key is everything that defines its episodes: Table III's F cells are Table II's CMPC
cells), with the code of the runs that made them, and runs the rest. Outputs in DIR: episodes.jsonl,
errors.jsonl (episodes that raised; retried on rerun), cells.csv, episodes.csv, table.md, a plot per outcome
(success, travel_time, collision, contact, discomfort, control_step, and robot_contact where robots can touch:
not in the paper) named OUTCOME_vs_humans.png, at one crowd size OUTCOME_vs_robots.png (--vary
scenario.robots) or OUTCOME_by_method.png, min_distance_hist.csv/.png, safety_tradeoff.png, sweep.json, and
with --record the MCAP logs in DIR/mcap/<cell>/. Every file's fields: docs/outputs.md. --episode-timeout S
stops an episode that runs past S s of wall-clock time (a controller that hangs) as an episode error, and the
sweep goes on.
"""
