"""benchmarks/batching.py: both batchings trained side by side on a small file, their padding as collated."""

import json

from tests.benchmark_modules import load_benchmark
from tests.predictors.samples import write_crowds

batching = load_benchmark("batching")


def test_a_small_run_reports_both_batchings(tmp_path, capsys, monkeypatch):
    """Five scenes of 3, 1, 2, 3 and 4 agents (13) in batches of 2: by_size (one chunk) batches them as
    1 2 | 3 3 | 4, 2 x 2 + 2 x 3 + 1 x 4 = 14 slots, one of them padding (1 / 13); shuffled pads at least
    as much."""
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    data = write_crowds(tmp_path / "crowds.ndjson")
    out = tmp_path / "b.json"
    argv = ["--train", str(data), "--batch-size", "2", "--epochs", "2", "--model", "vanilla_lstm"]
    assert batching.main([*argv, "--json", str(out)]) == 0
    shuffled, by_size = json.loads(out.read_text())["rows"]
    assert (shuffled["batching"], by_size["batching"]) == ("shuffled", "by_size")
    assert shuffled["batches"] == by_size["batches"] == 3
    assert shuffled["agents"] == by_size["agents"] == 2 * 13  # two epochs
    assert by_size["slots"] == 2 * 14 and by_size["padding"] == 1 / 13
    assert shuffled["slots"] >= by_size["slots"] and len(shuffled["epoch_times_s"]) == 2
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("vanilla_lstm training epochs on 5 scenes (the --train files), batch 2")
    assert [line.split()[0] for line in printed[2:]] == ["shuffled", "by_size"]
