"""A closed-loop calibration's --humans is a set of crowd sizes, as a sweep's is: the order they are written
in changes neither the episodes nor what the block records."""

import dataclasses

from pipelines.experiments.calibrate import ClosedLoopPlan


def test_the_order_of_the_crowd_sizes_changes_no_episode():
    written = [ClosedLoopPlan("constant_velocity", episodes=8, humans=h) for h in ((5, 7), (7, 5))]
    assert written[0].schedule() == written[1].schedule()
    assert dataclasses.asdict(written[0]) == dataclasses.asdict(written[1])


def test_the_default_sizes_keep_their_schedule():
    plan = ClosedLoopPlan("constant_velocity", episodes=4)
    assert plan.schedule() == [("circle", 5, 1_000_000), ("perpendicular", 5, 1_000_001),
                               ("circle", 6, 1_000_002), ("perpendicular", 6, 1_000_003)]  # fmt: skip
