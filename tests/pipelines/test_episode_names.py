"""An episode recording's file name and the repeat the review reads back from it (pipelines.logs.names)."""

from pipelines.logs.names import episode_filename, repeat_of
from pipelines.logs.recorder import UNFINISHED_SUFFIX


def test_the_repeat_is_read_from_a_finished_or_unfinished_file_of_its_seed_only():
    """A gym loop killed in its second episode of seed 3 leaves circle_seed000003_1.mcap.part, which the
    review reads: its own episode, as the finished file would be, not a copy of the seed's first."""
    second = episode_filename("circle", 3, repeat=1)
    assert second == "circle_seed000003_1.mcap"
    assert repeat_of(second, "circle", 3) == repeat_of(second + UNFINISHED_SUFFIX, "circle", 3) == 1
    assert repeat_of(episode_filename("circle", 3, repeat=12), "circle", 3) == 12
    for name, scenario, seed in [
        ("circle_seed000003.mcap", "circle", 3),  # the first
        ("circle_seed000003.mcap" + UNFINISHED_SUFFIX, "circle", 3),
        ("circle_seed000003_0.mcap", "circle", 3),  # no recorder names a repeat 0
        ("circle_seed000003_1.mcap", "circle", 4),  # another seed's
        ("circle_seed000003_1.mcap", "square", 3),
        ("circle_seed000003_1.mcap.bak", "circle", 3),
        ("circle_seed000003_1.mcap", None, 3),  # a run cut before its metadata
        ("circle_seed000003_1.mcap", "circle", True),
    ]:
        assert repeat_of(name, scenario, seed) == 0, name
