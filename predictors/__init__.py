"""Pedestrian trajectory predictors: one protocol, numeric (numpy/torch) and symbolic (CasADi) faces."""

from predictors.base import Predictor
from predictors.errors import CheckpointMismatch, DatasetFormatError, PredictorError, UnknownPredictor

__all__ = ["CheckpointMismatch", "DatasetFormatError", "Predictor", "PredictorError", "UnknownPredictor"]
