"""TrajNet++ data: reading and validating ndjson, converting raw BIWI EWAP annotations, statistics, locating
the files of an evaluation protocol, and the scene windows that training consumes.

Only ``datamodule`` imports Lightning, and only ``windows``, ``batching`` (a torch ``Sampler``) and
``datamodule`` import torch.
"""
