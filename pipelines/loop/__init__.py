"""The closed loop: scenario -> (controller -> simulator step) until the episode ends -> one record.

Imports the simulator, the MPC and the predictors; nothing of the logs, experiments or command line.
"""
