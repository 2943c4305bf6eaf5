"""AMCL over whole recorded runs against Nav2 Humble's own filter (`amcl_run_cases/`, see its README).

The twin's default mission's scans and odometry, fed to Nav2's compiled pf / motion / likelihood-field
code with recorded draws, gave Nav2's particle set after every update; the twin's `Amcl`, started from
the same particles and given the same draws, must have that set at every update (bitwise for the C
kernel, within 1e-9 for the numpy path) and publish the same pose and covariance.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from tests.unit.nav.amcl.drive_amcl import amcl_params, world
from twin.nav.amcl import filter as amcl_filter
from twin.nav.amcl.conformance_check import RecordedDraws
from twin.nav.amcl.filter import Amcl, LikelihoodField, as_received
from twin.nav.conformance import check_case, load_case
from twin.nav.frames import LaserGeometry

CASES = Path(__file__).with_name("amcl_run_cases")
FILES = sorted(CASES.glob("*.npz"))
DEFAULT = CASES / "default_seed0.npz"
INTERVAL_2 = CASES / "default_seed0_resample_interval_2.npz"


def test_the_recorded_runs_cover_the_issue() -> None:
    """At least 100 consecutive updates of the default run, TurtleBot3's parameters, Nav2's compiled filter."""
    meta, arrays = load_case(DEFAULT)
    assert meta["component"] == "amcl_run" and meta["oracle"] == "compiled"
    assert meta["nav2_commit"] == "3c3db59d6969d8ecee8e68468693d006397f4a0c"
    assert meta["updates"] >= 100 and len(arrays["set_sha256"]) == meta["updates"]
    assert meta["params"] == {k: v for k, v in dataclasses.asdict(amcl_params()).items() if k in meta["params"]}
    assert meta["params"]["recovery_alpha_slow"] == meta["params"]["recovery_alpha_fast"] == 0.0
    assert arrays["published"].all() and (arrays["update_uniforms"] > 0).all()  # resampled at every update
    counts = arrays["set_count"]
    assert counts.max() == 2000 and counts.min() < 600  # KLD-sampling shrinks the set and lets it grow again
    other, arrays2 = load_case(INTERVAL_2)
    assert other["params"]["resample_interval"] == 2 and 0 < arrays2["published"].sum() < other["updates"]
    world, arrays3 = load_case(CASES / "turtlebot3_world_seed0.npz")
    assert world["updates"] >= 50 and (arrays3["map"] == -1).any()  # another world, a map with unknown cells


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_the_twin_filter_equals_nav2_at_every_update(case: Path, native: bool) -> None:
    result = check_case(case, native=native)
    assert result.component == "amcl_run" and result.native is native
    assert result.equal, "; ".join(result.differences)


def _changed(tmp_path: Path, key: str, change: object) -> Path:
    meta, arrays = load_case(DEFAULT)
    arrays = dict(arrays)
    if callable(change):
        arrays[key] = change(arrays[key].copy())
    out = tmp_path / DEFAULT.name
    np.savez(out, meta=json.dumps(meta), **arrays)
    return out


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_the_checker_names_the_update_that_differs(tmp_path: Path, native: bool) -> None:
    """One stored weight a last bit away (C kernel) or 1e-8 away (numpy), one published y 1e-8 away: named."""

    def nudged(weighed: np.ndarray) -> np.ndarray:
        w = weighed[len(weighed) // 2, 3]
        weighed[len(weighed) // 2, 3] = np.nextafter(w, np.inf) if native else w + 1e-8
        return weighed

    result = check_case(_changed(tmp_path, "weighed_040", nudged), native=native)
    assert not result.equal
    first = result.differences[0]
    assert first.startswith("update 40 (scan ") and "after the motion and laser models" in first

    def moved(pose: np.ndarray) -> np.ndarray:
        pose[77, 1] += 1e-8
        return pose

    result = check_case(_changed(tmp_path, "pose", moved), native=native)
    assert not result.equal and result.differences[0].startswith("update 77 (scan ")
    assert "published y" in result.differences[0]


def test_w_slow_is_held_to_nav2s(tmp_path: Path) -> None:
    def moved(w_slow: np.ndarray) -> np.ndarray:
        w_slow[3:] = np.nextafter(w_slow[3:], np.inf)
        return w_slow

    result = check_case(_changed(tmp_path, "w_slow", moved), native=True)
    assert (
        not result.equal and result.differences[0].startswith("update 3 (scan ") and "w_slow" in result.differences[0]
    )


def test_a_digest_that_differs_is_reported_between_the_stored_sets(tmp_path: Path) -> None:
    def other(digests: np.ndarray) -> np.ndarray:
        digests[55] = "0" * 64
        return digests

    result = check_case(_changed(tmp_path, "set_sha256", other), native=True)
    assert not result.equal and result.differences[0].startswith("update 55 (scan ")


def test_amcl_takes_the_map_resolution_as_the_occupancy_grid_carries_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """Nav2's map scale is the OccupancyGrid's float32 resolution; with the float64 0.05 the run differs at once.

    The likelihood field then caps distances at int(2.0 / 0.05000000074505806) = 39 cells, not 40,
    and every distance is a multiple of the float32 scale: the first update's weights differ.
    """
    _, occupancy = world()
    received = as_received(occupancy)
    assert received.resolution_m == float(np.float32(0.05)) != 0.05
    assert received.origin_x_m == occupancy.origin_x_m and received.data is occupancy.data
    field = LikelihoodField(received, 2.0)
    assert field.resolution_m == received.resolution_m
    assert np.count_nonzero(field.distance_m < 2.0) < np.count_nonzero(LikelihoodField(occupancy, 2.0).distance_m < 2.0)
    monkeypatch.setattr(amcl_filter, "as_received", lambda occupancy: occupancy)
    result = check_case(DEFAULT, native=True)
    assert not result.equal and result.differences[0].startswith("update 0 (scan 0), after the motion and laser")


def test_between_resamplings_no_pose_is_published_and_the_first_comes_from_the_initial_clusters(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """resample_interval 2: Nav2 publishes amcl_pose only when it resampled (and on the first update,
    from pf_init's clusters of the initial set); every update still publishes the particle cloud."""
    _, occupancy = world()
    laser = LaserGeometry(angle_min_rad=0.0, angle_increment_rad=6.28 / 359, range_min_m=0.12, range_max_m=3.5)
    params = dataclasses.replace(amcl_params(), resample_interval=2)
    rng = np.random.default_rng(3)
    amcl = Amcl(params, occupancy, laser, rng)
    amcl.set_initial_pose(-2.0, -0.5, 0.0, np.diag([0.04, 0.04, 0.01]))
    initial = amcl_filter.cluster_estimate(amcl.poses, amcl.weights)
    ranges = np.full(360, 1.0, dtype=np.float32)
    first = amcl.process_scan((0.0, 0.0, 0.0), ranges)
    assert first is not None and amcl.updated and (first.x_m, first.y_m, first.yaw_rad) == initial[0]
    assert len(amcl.poses) == 2000  # the first update (count 1) did not resample
    assert amcl.process_scan((0.3, 0.0, 0.0), ranges) is not None and amcl.updated  # count 2: resampled
    assert len(amcl.poses) < 2000
    assert amcl.process_scan((0.6, 0.0, 0.0), ranges) is None and amcl.updated  # count 3: weighed only
    assert amcl.process_scan((0.61, 0.0, 0.0), ranges) is None and not amcl.updated  # gated
    # the recorded run holds the twin to it: publishing from the weighed set at every update differs
    publish_always = amcl_filter.Amcl._estimate

    def from_the_current_set(self: Amcl, odom_pose: tuple[float, float, float]) -> amcl_filter.AmclEstimate:
        self._clusters_now()
        return publish_always(self, odom_pose)

    monkeypatch.setattr(amcl_filter.Amcl, "_estimate", from_the_current_set)
    result = check_case(INTERVAL_2, native=True)
    assert not result.equal and result.differences[0].startswith("update 0 (scan 0): published x")


def test_set_particles_starts_the_filter_from_the_given_set() -> None:
    _, occupancy = world()
    laser = LaserGeometry(angle_min_rad=0.0, angle_increment_rad=6.28 / 359, range_min_m=0.12, range_max_m=3.5)
    amcl = Amcl(amcl_params(), occupancy, laser, RecordedDraws())
    poses = np.array([[-2.0, -0.5, 0.1], [-2.1, -0.4, 0.2], [-1.9, -0.6, 0.0]])
    amcl.set_particles(poses)
    assert np.array_equal(amcl.poses, poses) and amcl.poses is not poses
    assert np.array_equal(amcl.weights, np.full(3, 1.0 / 3)) and amcl.has_initial_pose


@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_the_bearings_are_nav2s(case: Path) -> None:
    """Nav2's bearings (the scan's float32 angles through tf2's quaternions) equal the twin's bit for bit."""
    meta, arrays = load_case(case)
    laser = LaserGeometry(**meta["laser"])
    bearings = amcl_filter.nav2_bearings(laser, len(arrays["bearings"]))
    assert np.array_equal(bearings, arrays["bearings"])
    plain = laser.angle_min_rad + np.arange(len(bearings)) * laser.angle_increment_rad  # the double increment
    assert 1e-7 < np.abs(plain - bearings).max() < 1e-6


def test_with_the_double_angle_increment_the_run_differs_at_its_second_update(monkeypatch: pytest.MonkeyPatch) -> None:
    def plain(laser: LaserGeometry, count: int) -> np.ndarray:
        return (
            laser.mount_yaw_rad + laser.angle_min_rad + np.arange(count, dtype=np.float64) * laser.angle_increment_rad
        )

    monkeypatch.setattr(amcl_filter, "nav2_bearings", plain)
    result = check_case(DEFAULT, native=True)
    assert not result.equal and result.differences[0].startswith("update 1 (scan 4), after the motion and laser")
