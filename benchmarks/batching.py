"""``crowdmpc train --batching``: the default ("shuffled") against "by_size" on the real training data, side
by side in one run.

A batch is padded to its largest scene, and the nets step through every agent slot (predictors/data/
batching.py). For each batching this trains a fresh net (same seed, ``--model``, Adam as ``crowdmpc train``)
through ``--epochs`` whole epochs of the training files of ``--protocol`` and ``--dataset`` (or ``--train``
files), the batchings' epochs interleaved so that the machine's load falls on all alike, and prints per
batching: the batches an epoch; the agent slots they held and the real agents in them, over all the epochs;
the padding (padded slots / real agents, as collated); the median and the best epoch time, each with its
ratio to "shuffled" (the best is the epoch other processes slowed least). An epoch is the data module's
training loader (the collation included) and a forward, backward and optimiser step per batch, without
Lightning's loop around it. One torch thread, as ``crowdmpc train`` runs. The machine is shared: the padding
does not depend on its load, the times do.

    nice -n 5 .venv/bin/python benchmarks/batching.py
    nice -n 5 .venv/bin/python benchmarks/batching.py --batch-size 32 --epochs 2 --json batching.json
    nice -n 5 .venv/bin/python benchmarks/batching.py --model vanilla_lstm --bucket-batches 4 16 64
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from pipelines.commands import check_data_files, path_arg
from pipelines.commands.train_data import (
    DATASET_SUFFIX,
    DEFAULT_DATASET,
    DEFAULT_PROTOCOL,
    PROTOCOLS,
    protocol_options,
)
from pipelines.errors import PipelineError

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import check_not_input, count_in, json_on_stdout, output_file, run_main, write_json  # noqa: E402

# The kinds PredictorModule trains (one loss, one optimiser); the GAN's two-step training is another loop.
MODELS = ("social_lstm", "vanilla_lstm", "social_gru", "social_attention")


def training_files(args: argparse.Namespace) -> list[Path]:
    if args.train:
        return list(args.train)
    from predictors.data.locate import protocol_files

    return protocol_files(args.data_dir, args.protocol, args.dataset, progress=False)["train"]


def _set_epoch(loader: Any, epoch: int) -> None:
    """What Lightning does as an epoch starts: ``set_epoch`` on the loader's sampler, else on its batch
    sampler's (``BySizeBatches.sampler``)."""
    sampler = loader.sampler if hasattr(loader.sampler, "set_epoch") else loader.batch_sampler.sampler
    sampler.set_epoch(epoch)


class Run:
    """One batching's data loader and net, trained an epoch at a time."""

    def __init__(self, batching: str, files: list[Path], args: argparse.Namespace, bucket: int | None):
        import torch

        from predictors.data.datamodule import TrajnetDataModule
        from predictors.optim_config import OptimConfig
        from predictors.training import make_module

        size, seed = args.batch_size, args.seed
        data = TrajnetDataModule(files, files, [], batch_size=size, seed=seed, batching=batching)
        data.setup("fit")
        self.loader = data.train_dataloader()
        if bucket is not None:  # the sampler's chunk, in place of the default the command uses
            self.loader.batch_sampler.bucket_batches = bucket  # type: ignore[union-attr]
        self.name = batching if bucket is None else f"{batching} k={bucket}"
        self.scenes = len(data.datasets["train"])
        torch.manual_seed(args.seed)
        self.module = make_module(args.model, None, OptimConfig())
        self.optimizer = self.module.configure_optimizers()[0][0]
        self.times: list[float] = []
        self.batches = self.slots = self.agents = 0

    def epoch(self, epoch: int) -> None:
        _set_epoch(self.loader, epoch)
        self.batches = 0
        started = time.perf_counter()
        for batch in self.loader:
            self.optimizer.zero_grad()
            self.module.model_step(batch, "train")["loss"].backward()
            self.optimizer.step()
            self.batches += 1
            self.slots += batch.positions.shape[0] * batch.positions.shape[2]
            self.agents += int(batch.mask.any(dim=1).sum())
        self.times.append(time.perf_counter() - started)

    def row(self, reference: tuple[float, float]) -> dict[str, Any]:
        seconds, best = statistics.median(self.times), min(self.times)
        return {
            "batching": self.name,
            "batches": self.batches,
            "slots": self.slots,
            "agents": self.agents,
            "padding": (self.slots - self.agents) / self.agents,
            "epoch_s": seconds,
            "best_epoch_s": best,
            "epoch_times_s": self.times,
            "ratio": seconds / reference[0] if reference[0] else float("nan"),
            "best_ratio": best / reference[1] if reference[1] else float("nan"),
        }


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", choices=MODELS, default="social_lstm")
    parser.add_argument("--batch-size", type=count_in("batch size", 1), default=8, help="as crowdmpc train")
    parser.add_argument("--epochs", type=count_in("epochs", 1), default=3, help="timed epochs a batching")
    parser.add_argument(
        "--bucket-batches",
        type=count_in("bucket batches", 1),
        nargs="+",
        default=None,
        metavar="K",
        help="by_size with these chunks of K batches (default: the one crowdmpc train uses)",
    )
    parser.add_argument("--seed", type=count_in("seed", 0), default=0)
    parser.add_argument("--data-dir", default=None, help="data directory (default: $CROWDMPC_DATA)")
    # None by default: given with --train files, they are refused, as crowdmpc train refuses them
    parser.add_argument("--protocol", choices=PROTOCOLS, default=None, help=f"default {DEFAULT_PROTOCOL}")
    parser.add_argument(
        "--dataset", choices=tuple(DATASET_SUFFIX), default=None, help=f"default {DEFAULT_DATASET}"
    )
    parser.add_argument("--train", nargs="+", type=path_arg, default=None, metavar="FILE", help="instead")
    parser.add_argument("--json", type=output_file, help="also write the rows to this file")
    args = parser.parse_args(argv)
    # Here, before torch and Lightning are imported (a minute on a cold machine): a missing file was refused
    # only after them, by the data module.
    try:
        # they were ignored without a word: the run trained on the --train files alone
        protocol_options(args, bool(args.train), files="--train")
        if args.train:
            check_data_files("--train", args.train)
        elif args.data_dir is not None and not Path(args.data_dir).is_dir():
            raise PipelineError(f"--data-dir {args.data_dir} is not a directory")
    except PipelineError as exc:
        parser.error(str(exc))
    check_not_input(parser, "--json", args.json, args.train or [])
    if not args.train:  # --train files: no protocol or dataset (null in the --json file's args)
        args.protocol, args.dataset = args.protocol or DEFAULT_PROTOCOL, args.dataset or DEFAULT_DATASET
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    with json_on_stdout(args.json):
        files = training_files(args)  # before torch: the protocol's data refused (or prepared) without it
        import torch

        from predictors.data.batching import BUCKET_BATCHES
        from predictors.text_table import counted

        torch.set_num_threads(1)
        runs = [Run("shuffled", files, args, None)]
        runs += [Run("by_size", files, args, k) for k in (args.bucket_batches or [None])]
        source = "the --train files" if args.train else f"the {args.protocol} {args.dataset} training files"
        print(
            f"{args.model} training epochs on {runs[0].scenes} scenes ({source}), batch {args.batch_size}, "
            f"by_size chunks of {BUCKET_BATCHES} batches unless k= says; 1 torch thread; "
            f"{counted(args.epochs, 'interleaved epoch')} each"
        )
        print(
            f"{'batching':<14} | {'batches':>7} {'slots':>7} {'agents':>7} {'padding':>8} | "
            f"{'median s':>8} {'ratio':>6} | {'best s':>6} {'ratio':>6}"
        )
        for epoch in range(args.epochs):
            for run in runs:
                run.epoch(epoch)
        reference = statistics.median(runs[0].times), min(runs[0].times)
        rows = [run.row(reference) for run in runs]
        for row in rows:
            print(
                f"{row['batching']:<14} | {row['batches']:>7} {row['slots']:>7} {row['agents']:>7} "
                f"{row['padding']:>7.1%} | {row['epoch_s']:>8.2f} {row['ratio']:>5.2f}x | "
                f"{row['best_epoch_s']:>6.2f} {row['best_ratio']:>5.2f}x",
                flush=True,
            )
        if args.json is not None:
            write_json(args.json, {"args": vars(args), "files": [str(f) for f in files], "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
