"""Automatic torch -> CasADi export of predictor nets (``export_function``), with its one error type.

``symbolic`` holds the symbolic tensor torch code runs on; ``elementwise``, ``movement``, ``linalg``,
``layers`` and ``attention`` the operations, which ``ops`` enters in the dispatch tables; ``trace`` the run
(and the layers it replaces: the recurrent cells, nn.MultiheadAttention, and from ``transformer``
nn.TransformerEncoderLayer and nn.TransformerEncoder) and the ``casadi.Function`` it becomes; ``parity`` the
check against torch.
"""

from predictors.export.errors import ExportError
from predictors.export.trace import TensorSpec, export_function, output_shapes

__all__ = ["ExportError", "TensorSpec", "export_function", "output_shapes"]
