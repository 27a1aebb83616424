"""Predictor plugins the tests register (``crowdmpc --plugin tests.plugins.toy_predictor:ToyNet``)."""
