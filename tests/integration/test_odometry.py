"""Issue 4 end to end: the EKF's /odom against /ground_truth/odom over a 120 s drive with turns.

The drive is open loop (a cmd_vel script of straights, arcs and turns in place) in an empty world,
so every run drives the same path whatever its odometry says, with the twin's default sensor noise
and disturbances; each run records a bag, and the test reads it back.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from scipy.stats import chi2

from twin.robot.disturbances import Disturbances, WheelSlip
from twin.sim.scenario import Scenario
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation

DRIVE_S = 120.0
NEES_RUNS = 10


def _yaw(q: object) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))  # type: ignore[attr-defined]


class Run:
    """The /odom estimates and the ground truth at the same stamps."""

    def __init__(self, bag: Path) -> None:
        est: dict[int, tuple[float, float, float, np.ndarray]] = {}
        truth: dict[int, tuple[float, float, float]] = {}
        with AnyReader([bag]) as reader:
            cons = [c for c in reader.connections if c.topic in ("/odom", "/ground_truth/odom")]
            for con, t_ns, raw in reader.messages(connections=cons):
                msg = reader.deserialize(raw, con.msgtype)
                p = msg.pose.pose.position
                if con.topic == "/odom":
                    est[t_ns] = (p.x, p.y, _yaw(msg.pose.pose.orientation), np.array(msg.pose.covariance))
                else:
                    truth[t_ns] = (p.x, p.y, _yaw(msg.pose.pose.orientation))
        self.stamps = sorted(set(est) & set(truth))
        assert len(self.stamps) > 0.9 * len(truth)
        self.est = [est[t] for t in self.stamps]
        self.truth = [truth[t] for t in self.stamps]
        xy = np.array([t[:2] for t in self.truth])
        self.distance_m = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))

    def final_errors(self) -> tuple[float, float]:
        (x, y, yaw, _), (tx, ty, tyaw) = self.est[-1], self.truth[-1]
        return math.hypot(x - tx, y - ty), abs(math.remainder(yaw - tyaw, math.tau))

    def nees(self) -> np.ndarray:
        out = []
        for (x, y, yaw, cov), (tx, ty, tyaw) in zip(self.est, self.truth, strict=True):
            c = cov.reshape(6, 6)[np.ix_((0, 1, 5), (0, 1, 5))]
            e = np.array([x - tx, y - ty, math.remainder(yaw - tyaw, math.tau)])
            out.append(float(e @ np.linalg.solve(c, e)))
        return np.array(out[1:])  # the first estimate is the initial pose itself


def simulate(scenario: Scenario, bag: Path) -> Run:
    with Simulation(scenario, bag_path=bag, duration_s=DRIVE_S) as sim:
        summary = sim.run()
    assert summary.sim_s == pytest.approx(DRIVE_S)
    assert summary.contacts == 0
    return Run(bag)


DRIVE = """\
name: ekf_drive
world: {{sdf: {world}}}
drive: {{type: kinematic}}          # per-wheel slip (below) is the kinematic drive's; the FMU chassis slips both alike
mission:
  type: cmd_vel_script
  segments:                         # 120 s: straights, arcs both ways, turns in place, stops
    - {{duration_s: 12, linear_mps: 0.2}}
    - {{duration_s: 10, linear_mps: 0.15, angular_radps: 0.3}}
    - {{duration_s: 5, angular_radps: 1.0}}
    - {{duration_s: 3}}
    - {{duration_s: 15, linear_mps: 0.22}}
    - {{duration_s: 12, linear_mps: 0.2, angular_radps: -0.4}}
    - {{duration_s: 8, angular_radps: -0.8}}
    - {{duration_s: 14, linear_mps: 0.2, angular_radps: 0.1}}
    - {{duration_s: 2}}
    - {{duration_s: 10, linear_mps: 0.18, angular_radps: 0.5}}
    - {{duration_s: 16, linear_mps: 0.22, angular_radps: -0.05}}
    - {{duration_s: 6, angular_radps: 0.6}}
    - {{duration_s: 7, linear_mps: 0.1}}
"""


@pytest.fixture(scope="module")
def scenario(fixtures: Path, tmp_path_factory: pytest.TempPathFactory) -> Scenario:
    path = tmp_path_factory.mktemp("drive") / "drive.yaml"
    path.write_text(DRIVE.format(world=fixtures / "gazebo_classic" / "worlds" / "empty_world.world"))
    return load_scenario(path)


def test_default_noise_final_error_within_one_percent_of_distance_and_two_degrees(
    scenario: Scenario, tmp_path: Path
) -> None:
    run = simulate(scenario, tmp_path / "bag")
    position_m, yaw_rad = run.final_errors()
    print(
        f"\n{run.distance_m:.2f} m in {DRIVE_S:.0f} s: final error {1000 * position_m:.1f} mm, {math.degrees(yaw_rad):.3f} deg"
    )
    assert run.distance_m > 15.0
    assert position_m <= 0.01 * run.distance_m
    assert math.degrees(yaw_rad) <= 2.0


def test_with_wheel_slip_fusing_the_gyro_beats_encoders_alone(scenario: Scenario, tmp_path: Path) -> None:
    slipping = dataclasses.replace(
        scenario, disturbances=Disturbances(wheel_slip=WheelSlip(left_fraction=0.05, right_fraction=0.0))
    )
    wheels_only = dataclasses.replace(slipping, estimation=dataclasses.replace(slipping.estimation, fuse_gyro=False))
    wheels = simulate(wheels_only, tmp_path / "wheels")
    fused = simulate(slipping, tmp_path / "fused")
    (wp, wy), (fp, fy) = wheels.final_errors(), fused.final_errors()
    print("\n5 % slip on the left wheel, 120 s drive         position     yaw")
    print(f"  encoders only                                {wp:7.3f} m  {math.degrees(wy):6.2f} deg")
    print(f"  encoders + gyro (EKF)                        {fp:7.3f} m  {math.degrees(fy):6.2f} deg")
    assert fp < wp / 3
    assert fy < wy / 3
    assert math.degrees(fy) < 1.0


def test_nees_inside_the_95_percent_chi_square_bounds_for_90_percent_of_samples(
    scenario: Scenario, tmp_path: Path
) -> None:
    # Monte Carlo NEES over independent seeds: at each sample, the mean over N runs of e' P^-1 e for
    # (x, y, yaw) must lie inside chi2(3N)/N's 95 % interval (one run's errors are random walks, so
    # its own NEES samples are not independent; averaging over runs is the standard test).
    runs = [simulate(dataclasses.replace(scenario, seed=seed), tmp_path / f"s{seed}") for seed in range(NEES_RUNS)]
    length = min(len(r.stamps) for r in runs)
    nees = np.array([r.nees()[: length - 1] for r in runs])
    average = nees.mean(axis=0)
    lo, hi = chi2.ppf(0.025, 3 * NEES_RUNS) / NEES_RUNS, chi2.ppf(0.975, 3 * NEES_RUNS) / NEES_RUNS
    inside = float(np.mean((average >= lo) & (average <= hi)))
    print(
        f"\nNEES over {NEES_RUNS} runs: mean {nees.mean():.2f} (3 if consistent), {100 * inside:.1f} % of samples inside [{lo:.2f}, {hi:.2f}]"
    )
    assert inside >= 0.90
