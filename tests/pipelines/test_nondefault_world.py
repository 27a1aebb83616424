"""`crowdmpc simulate` with [world] values other than the paper's: what it prints follows them."""

import json

import pytest

from pipelines.cli import main


@pytest.mark.parametrize(("radius", "label"), [(0.3, "contact (<0.6 m)"), (0.45, "contact (<0.9 m)")])
def test_the_printed_contact_threshold_is_the_runs_sum_of_radii(tmp_path, capsys, radius, label):
    """Contact is a centre distance below the sum of the radii, 2 x [world] radius (crowdsim.metrics). With
    radius 0.45 the table read "contact (<0.6 m) 100 %" over episodes whose closest approach was 0.62 to
    0.83 m, under "collision (<0.8 m) 75 %": a contact that is no collision."""
    out = tmp_path / "run.json"
    argv = ["simulate", "--controller", "straight", "--humans", "5", "--episodes", "4", "--no-progress"]
    assert main([*argv, "--set", f"world.radius={radius}", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert label in printed
    episodes = [e["metrics"] for e in json.loads(out.read_text())["episodes"]]
    assert all(e["contact"] == (e["min_distance"] < 2 * radius) for e in episodes)
    if radius != 0.3:  # some episode whose contact only the run's threshold explains
        assert any(e["contact"] and e["min_distance"] >= 0.6 for e in episodes)
