"""AMCL against Nav2 Humble's own nav2_amcl: every case in `amcl_cases/` (recorded from Nav2's code, see its README).

The motion model is given the standard normal draws Nav2's `pf_ran_gaussian` consumed; equal means
bitwise for the C kernel, within 1e-12 m / rad for the numpy path (numpy's own sin, cos and atan2).
The likelihood field's distances and each particle's weight before normalisation, and KLD resampling's
samples given Nav2's uniform draws, are bitwise equal on both paths; the published pose and covariance
bitwise for the C kernel, within 1e-12 for numpy (`twin.nav.amcl.conformance_check`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.unit.nav.amcl.drive_amcl import amcl_params, world
from twin.nav.amcl.conformance_check import RecordedDraws
from twin.nav.amcl.filter import Amcl, odometry_update
from twin.nav.conformance import check_case, load_case
from twin.nav.frames import LaserGeometry

CASES = Path(__file__).with_name("amcl_cases")
FILES = sorted(CASES.glob("*.npz"))


def test_the_recorded_set_covers_the_issue() -> None:
    metas = [load_case(f)[0] for f in FILES]
    motion = [m for m in metas if m["component"] == "amcl_motion_model"]
    likelihood = [m for m in metas if m["component"] == "amcl_likelihood_field"]
    assert len(motion) + len(likelihood) >= 100 and len(motion) >= 50 and len(likelihood) >= 50
    assert {"backward", "pure_rotation", "near_zero_translation", "turn_near_pi"} <= {m["group"] for m in motion}
    groups = {m["group"] for m in likelihood}
    assert {"house_tb3_params", "tb3_world_tb3_params", "house_varied_params", "house_cell_edges"} <= groups
    resample = [m for m in metas if m["component"] == "amcl_resample"]
    assert len(resample) >= 40 and {"tight", "spread", "multimodal", "one_heavy", "boundary"} <= {
        m["group"] for m in resample
    }
    estimate = [m for m in metas if m["component"] == "amcl_estimate"]
    assert len(estimate) >= 30 and {"two_modes", "four_modes", "seam", "unfolded"} <= {m["group"] for m in estimate}
    assert {m["nav2_commit"] for m in metas} == {"3c3db59d6969d8ecee8e68468693d006397f4a0c"}
    assert {m["oracle"] for m in metas} == {"compiled"}


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_amcl_equals_nav2(case: Path, native: bool) -> None:
    result = check_case(case, native=native)
    assert result.component.startswith("amcl_") and result.native is native
    assert result.equal, "; ".join(result.differences)


def _changed(tmp_path: Path, source: Path, key: str, change: float) -> Path:
    meta, arrays = load_case(source)
    arrays[key] = arrays[key].copy()
    arrays[key].ravel()[len(arrays[key].ravel()) // 2] += change
    out = tmp_path / source.name
    np.savez(out, meta=json.dumps(meta), **arrays)
    return out


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_a_moved_particle_or_weight_is_named(tmp_path: Path, native: bool) -> None:
    """The checkers are not blind: one coordinate moved by 1e-11, one weight by a relative 1e-15, is reported."""
    motion = next(f for f in FILES if f.name.startswith("motion_"))
    result = check_case(_changed(tmp_path, motion, "poses_after", 1e-11), native=native)
    assert not result.equal and "particles differ" in result.differences[0]
    weighed = next(f for f in FILES if f.name.startswith("likelihood_house"))
    _, arrays = load_case(weighed)
    middle = arrays["weights_after"].ravel()[len(arrays["weights_after"]) // 2]
    result = check_case(_changed(tmp_path, weighed, "weights_after", float(np.spacing(middle))), native=native)
    assert not result.equal and "weights: 1 of" in result.differences[0]
    drawn = next(f for f in FILES if f.name.startswith("resample_"))
    result = check_case(_changed(tmp_path, drawn, "poses_after", 1e-9), native=native)
    assert not result.equal and "samples" in result.differences[0]
    published = next(f for f in FILES if f.name.startswith("estimate_"))
    meta, arrays = load_case(published)
    meta["covariance"]["yx"] = float(np.nextafter(meta["covariance"]["yx"], np.inf))
    moved = tmp_path / published.name
    np.savez(moved, meta=json.dumps(meta), **arrays)
    result = check_case(moved, native=True)
    assert not result.equal and "covariance yx" in result.differences[0]


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_sampled_rotations_are_folded_as_nav2_folds_them(native: bool) -> None:
    """Straight back, rot1 = rot2 = -pi; Nav2's angle_diff(rot, sd z) folds each sampled rotation into [-pi, pi].

    With no noise on rot2, angle_diff(-pi, 0) is +pi; a rot1 pushed below -pi comes out near +pi. The
    yaw changes by the folded sum, not by rot1 + rot2 - noise (which is a turn away from Nav2's).
    """
    pose, delta = (0.0, 0.0, 0.0), (-0.3, 0.0, 0.0)
    alphas = (0.2, 0.2, 0.2, 0.2)
    draws = RecordedDraws(np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    poses = odometry_update(np.zeros((2, 3)), pose, delta, alphas, draws, native=native)
    sd = math.sqrt(0.2 * 0.3 * 0.3)  # both rotations' sd: alpha2 trans^2 (the rotations count as 0 or pi: no noise)
    assert poses[0, 2] == pytest.approx(sd, abs=1e-12)  # (-pi + sd) + pi
    assert poses[1, 2] == pytest.approx(2.0 * math.pi - sd, abs=1e-12)  # (pi - sd) + pi
    assert poses[0, 0] == pytest.approx(-0.3 * math.cos(sd), abs=1e-12)


def test_the_filter_takes_its_motion_draws_from_the_source_it_is_given() -> None:
    """A replayed draw source drives Amcl's motion update: the particles move as odometry_update moves them with those draws."""
    _, occupancy = world()
    laser = LaserGeometry(angle_min_rad=0.0, angle_increment_rad=6.28 / 359, range_min_m=0.12, range_max_m=3.5)
    params = dataclasses.replace(amcl_params(), resample_interval=3)  # no resampling in the first two updates
    n = params.max_particles
    rng = np.random.default_rng(7)
    initial, motion = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    amcl = Amcl(params, occupancy, laser, RecordedDraws(np.concatenate([initial, motion])))
    amcl.set_initial_pose(-2.0, -0.5, 0.0, np.diag([0.01, 0.01, 0.01]))
    before = amcl.poses.copy()
    ranges = np.full(360, np.inf, dtype=np.float32)  # no beam weighs: only the motion model moves them
    amcl.process_scan((0.0, 0.0, 0.0), ranges)
    amcl.process_scan((0.3, 0.05, 0.0), ranges)
    want = odometry_update(
        before.copy(), (0.3, 0.05, 0.0), (0.3, 0.05, 0.0), (0.2, 0.2, 0.2, 0.2), RecordedDraws(motion)
    )
    assert np.array_equal(amcl.poses, want)
