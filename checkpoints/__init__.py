"""The shipped model zoo as package data (installed as ``crowdmpc_checkpoints``; see README.md here).

No code: ``predictors.zoo.checkpoints_dir`` locates this directory, in a clone or installed.
"""
