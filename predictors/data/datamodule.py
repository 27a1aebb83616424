"""A Lightning ``DataModule`` over TrajNet++ scene windows (the only data module that imports Lightning)."""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Final

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader

from predictors.base import OBS_LEN, PRED_LEN
from predictors.data.batching import BySizeBatches, check_batching
from predictors.data.windows import EpochShuffle, TrajnetSceneDataset, collate_scenes, path_list
from predictors.errors import DatasetFormatError, PredictorError

MAX_SEED: Final[int] = 2**64  # exclusive: torch.Generator.manual_seed takes 0 .. 2**64 - 1


class TrajnetDataModule(L.LightningDataModule):
    """Train/val/test ``SceneBatch`` loaders over lists of TrajNet++ ndjson files.

    Training batches are shuffled and (with ``augment``) randomly rotated, both functions of ``seed`` and
    the epoch (``EpochShuffle``), so a resumed run continues as an uninterrupted one; validation and test
    batches are neither. ``batching`` cuts the training batches (``predictors.data.batching``): "shuffled"
    as the shuffled order comes, "by_size" from buckets of scenes of similar agent counts.
    """

    def __init__(
        self,
        train_files: Sequence[str | Path],
        val_files: Sequence[str | Path],
        test_files: Sequence[str | Path],
        batch_size: int = 64,
        augment: bool = True,
        seed: int = 0,
        num_workers: int = 0,
        obs_len: int = OBS_LEN,
        pred_len: int = PRED_LEN,
        batching: str = "shuffled",
    ):
        super().__init__()
        for what, count in (("batch_size", batch_size), ("num_workers", num_workers)):
            # "8" from a YAML file met a bare TypeError in the comparison below
            if not isinstance(count, int) or isinstance(count, bool):
                raise PredictorError(f"{what} must be an int, got {type(count).__name__} {count!r}")
        if batch_size < 1:
            raise PredictorError(f"batch_size must be >= 1, got {batch_size}")
        if num_workers < 0:
            raise PredictorError(f"num_workers must be >= 0, got {num_workers}")
        seed = _seed(seed)
        # a string ("no" from a file) is true, and rotated the training scenes it was to leave alone
        if not isinstance(augment, (bool, np.bool_)):
            raise PredictorError(f"augment must be True or False, got {type(augment).__name__} {augment!r}")
        augment = bool(augment)
        self.files = {
            split: path_list(files, f"{split}_files")
            for split, files in (("train", train_files), ("val", val_files), ("test", test_files))
        }
        self.batch_size = batch_size
        self.augment = augment
        self.seed = seed
        self.num_workers = num_workers
        self.obs_len = obs_len
        self.pred_len = pred_len
        self.batching = check_batching(batching)
        self.datasets: dict[str, TrajnetSceneDataset] = {}
        # under the constructor's own names, as strings (a checkpoint loads with weights_only=True), so that
        # ``TrajnetDataModule.load_from_checkpoint`` rebuilds this module
        self.save_hyperparameters(
            {
                **{f"{k}_files": [str(p) for p in v] for k, v in self.files.items()},
                "batch_size": batch_size,
                "augment": augment,
                "seed": seed,
                "num_workers": num_workers,
                "obs_len": obs_len,
                "pred_len": pred_len,
                "batching": batching,
            }
        )

    def _dataset(self, split: str) -> TrajnetSceneDataset:
        if split not in self.datasets:
            if not self.files[split]:
                raise PredictorError(f"no {split} files were given to the data module")
            dataset = TrajnetSceneDataset(
                self.files[split],
                obs_len=self.obs_len,
                pred_len=self.pred_len,
                augment=self.augment and split == "train",
                seed=self.seed,
                # validation picks the epoch that evaluation would score best: read as evaluation reads
                # (each scene's end); training takes whole scenes of exactly its length
                window="whole" if split == "train" else "last",
            )
            if split in ("train", "val") and len(dataset) == 0:
                # An empty split is a valid file, but nothing to train on or to select the best epoch by
                # (the shuffling sampler fails obscurely, and an empty validation leaves no val metrics).
                purpose = "training" if split == "train" else "validation"
                if len(self.files[split]) == 1:
                    raise DatasetFormatError(
                        self.files[split][0], None, f"holds no scenes; {purpose} needs one"
                    )
                names = ", ".join(str(f) for f in self.files[split])
                raise PredictorError(f"the {split} files hold no scenes; {purpose} needs one: {names}")
            self.datasets[split] = dataset
        return self.datasets[split]

    def setup(self, stage: str | None = None) -> None:
        wanted = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",), "predict": ("test",)}
        for split in wanted.get(stage, ("train", "val", "test")) if stage else ("train", "val", "test"):
            if self.files[split]:
                self._dataset(split)

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        dataset = self._dataset(split)
        if shuffle and self.batching == "by_size":
            return DataLoader(
                dataset,
                batch_sampler=BySizeBatches(
                    EpochShuffle(dataset, self.seed), dataset.agent_counts(), self.batch_size
                ),
                num_workers=self.num_workers,
                collate_fn=partial(collate_scenes, obs_len=self.obs_len),
                generator=torch.Generator().manual_seed(self.seed),
                persistent_workers=self.num_workers > 0,
            )
        return DataLoader(
            dataset,
            batch_size=self.batch_size,
            sampler=EpochShuffle(dataset, self.seed) if shuffle else None,
            num_workers=self.num_workers,
            collate_fn=partial(collate_scenes, obs_len=self.obs_len),
            # the workers' base seeds (the order and angles do not depend on them)
            generator=torch.Generator().manual_seed(self.seed) if shuffle else None,
            persistent_workers=self.num_workers > 0,
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", shuffle=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", shuffle=False)

    def predict_dataloader(self) -> DataLoader:
        """The test scenes in order, for ``Trainer.predict`` (``_PredictorModule.predict_step``'s output)."""
        return self._loader("test", shuffle=False)


def _seed(seed: object) -> int:
    """``seed`` as an int, checked where it is given: it seeds the loaders' torch generators and the epochs'
    orders and angles (``default_rng([seed, epoch])``), which took a str or a negative seed to the first
    training batch, inside the fit, and failed there in words naming no seed ("manual_seed expected a long,
    but got str", "expected non-negative integer"), and refused numpy's integers (torch's generator)."""
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise PredictorError(f"seed must be an int, got {type(seed).__name__} {seed!r}")
    if not 0 <= int(seed) < MAX_SEED:
        raise PredictorError(f"seed must be in 0..{MAX_SEED - 1} (a torch generator's range), got {seed}")
    return int(seed)
