"""benchmarks/pooling.py: both paths measured in processes of their own, side by side, on one small run."""

import json

from tests.benchmark_modules import load_benchmark

pooling = load_benchmark("pooling")


def test_the_scenes_keep_the_density_as_the_crowd_grows():
    """The spread grows as sqrt(N): the mean distance to the nearest agent stays about the same."""
    import torch

    nearest = []
    for n in (20, 320):
        positions, mask = pooling.scenes(4, n)
        assert positions.shape == (4, pooling.STEPS, n, 2) and mask.all()
        d = torch.cdist(positions[:, 0], positions[:, 0]) + torch.eye(n) * 1e9
        nearest.append(float(d.min(dim=-1).values.mean()))
    assert 0.7 < nearest[0] / nearest[1] < 1.5


def test_a_small_run_reports_both_paths_for_each_crowd(tmp_path, capsys):
    out = tmp_path / "p.json"
    argv = ["--agents", "3", "6", "--batch", "2", "--repeats", "1", "--pooling", "soft", "--json", str(out)]
    assert pooling.main(argv) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [row["agents"] for row in rows] == [3, 6]
    for row in rows:
        for mode in pooling.MODES:
            assert row[mode]["seconds"] > 0 and row[mode]["peak_mb"] > 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("Social-LSTM soft pooling, train step, B = 2")
    assert [line.split()[0] for line in printed[2:]] == ["3", "6"]
