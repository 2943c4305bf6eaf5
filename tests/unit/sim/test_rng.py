from __future__ import annotations

import numpy as np

from twin.sim.rng import RngStreams


def test_a_namespace_gives_a_robot_its_own_streams() -> None:
    rng = RngStreams(7)
    one, two = rng.under("robot1"), rng.under("robot2")
    a, b = one.stream("lidar").normal(size=4), two.stream("lidar").normal(size=4)
    assert not np.array_equal(a, b)
    assert np.array_equal(a, RngStreams(7).stream("robot1/lidar").normal(size=4))


def test_no_namespace_keeps_the_single_robots_stream_names() -> None:
    rng = RngStreams(7)
    assert rng.under("") is rng
    assert np.array_equal(rng.under("/").stream("lidar").normal(size=3), RngStreams(7).stream("lidar").normal(size=3))
