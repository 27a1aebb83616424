"""How ``crowdmpc train`` cuts an epoch's scenes into batches (``--batching``).

A batch is padded to its largest scene (``collate_scenes``): the ETH + Hotel training scenes hold 3 to 28
agents (11.6 on average), so a batch of 8 drawn at random holds 0.62 padded agent slots per real agent
(benchmarks/batching.py), and the nets step through every slot. ``"shuffled"`` (the default, as TrajNet++
trains) cuts the epoch's shuffled order (``EpochShuffle``) into batches as it comes. ``"by_size"``
(``BySizeBatches``) is the usual bucket iterator: the same shuffled order, cut into chunks of
``bucket_batches`` batches, each chunk sorted by agent count and cut into batches, the batches then
shuffled. Its batches hold scenes of similar size (less padding, faster epochs) but no longer mix dense and
sparse scenes, so it trains other weights than "shuffled" from the same seed.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Final

import numpy as np
from torch.utils.data import Sampler

from predictors.data.windows import EpochShuffle
from predictors.errors import PredictorError

BATCHINGS: Final = ("shuffled", "by_size")
# Batches per sorted chunk of "by_size": the larger, the more alike the sizes in a batch and the fewer
# orders an epoch can take (one chunk of the whole epoch: the same batches every epoch, in another order).
# 16 batches of 8 scenes: the 736 ETH + Hotel training scenes in 6 chunks (benchmarks/batching.py).
BUCKET_BATCHES: Final[int] = 16


def check_batching(batching: str) -> str:
    """``batching`` when it is one of ``BATCHINGS``, else PredictorError naming them."""
    if batching not in BATCHINGS:
        raise PredictorError(f"batching {batching!r} is not one of {list(BATCHINGS)}")
    return batching


class BySizeBatches(Sampler[list[tuple[int, int]]]):
    """Batches of ``batch_size`` item keys ``(index, epoch)`` (the keys ``EpochShuffle`` hands out) whose
    items have similar ``sizes`` (agents per scene, ``TrajnetSceneDataset.agent_counts``).

    Each epoch: the order ``shuffle`` gives that epoch (``default_rng([seed, epoch]).permutation``) is cut
    into chunks of ``bucket_batches * batch_size`` items; each chunk is sorted by size (a stable sort: equal
    sizes keep the shuffled order) and cut into batches of ``batch_size``; the batches are then put in an
    order drawn from the same generator. Every item comes once an epoch, in ``ceil(len / batch_size)``
    batches (only the last chunk's last batch can be short), as with "shuffled". The order is a function of
    ``(seed, epoch)`` alone: Lightning calls ``set_epoch`` on a batch sampler's ``sampler`` (here
    ``shuffle``) as each epoch starts, after restoring a checkpoint's epoch, so a resumed run batches as an
    uninterrupted one.
    """

    def __init__(
        self,
        shuffle: EpochShuffle,
        sizes: np.ndarray,
        batch_size: int,
        bucket_batches: int = BUCKET_BATCHES,
    ):
        if batch_size < 1 or bucket_batches < 1:
            raise PredictorError(
                f"need batch_size >= 1 and bucket_batches >= 1, got {batch_size} and {bucket_batches}"
            )
        sizes = np.asarray(sizes)
        if sizes.shape != (len(shuffle),):
            raise PredictorError(f"need one size per item ({len(shuffle)}), got an array of {sizes.shape}")
        self.sampler = shuffle  # the name Lightning looks for to call set_epoch
        self.sizes = sizes
        self.batch_size = batch_size
        self.bucket_batches = bucket_batches

    def __len__(self) -> int:
        return math.ceil(len(self.sampler) / self.batch_size)

    def __iter__(self) -> Iterator[list[tuple[int, int]]]:
        seed, epoch = self.sampler.seed, self.sampler.epoch
        rng = np.random.default_rng([seed, epoch])
        order = rng.permutation(len(self.sampler))  # EpochShuffle's order of this epoch, drawn as it draws it
        chunk = self.bucket_batches * self.batch_size
        batches = []
        for start in range(0, len(order), chunk):
            part = order[start : start + chunk]
            part = part[np.argsort(self.sizes[part], kind="stable")]
            batches += [part[i : i + self.batch_size] for i in range(0, len(part), self.batch_size)]
        for b in rng.permutation(len(batches)):
            yield [(int(i), epoch) for i in batches[b]]
