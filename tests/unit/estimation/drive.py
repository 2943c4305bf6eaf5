"""Drive the sensor models and the EKF along a ground-truth trajectory (the loop, until the lead's runs it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.estimation import EstimationSection, OdometryEstimate, OdometryFilter
from twin.robot.disturbances import Disturbances
from twin.robot.encoders import EncoderModel, EncoderSpec
from twin.robot.imu import ImuModel, ImuSpec
from twin.robot.trajectory import Trajectory

WHEEL_RADIUS_M = 0.033
WHEEL_SEPARATION_M = 0.287
STEP_NS = 33_333_333  # joint states at 30 Hz


def make_filter(
    config: EstimationSection | None = None, pose: tuple[float, float, float] = (0.0, 0.0, 0.0), *, native: bool = True
) -> OdometryFilter:
    """A TurtleBot3 filter (default config) at `pose`."""
    return OdometryFilter(
        config or EstimationSection(),
        wheel_radius_m=WHEEL_RADIUS_M,
        wheel_separation_m=WHEEL_SEPARATION_M,
        initial_pose=pose,
        native=native,
    )


def feed_perfect_wheels(
    odom: OdometryFilter, seconds: float, v: float, w: float, *, gyro: float | None = None, start: int = 0
) -> int:
    """Feed perfect wheels (and six gyro readings `gyro` per step, default the true rate) for `seconds`.

    Returns the next step index, to continue from.
    """
    r, b = WHEEL_RADIUS_M, WHEEL_SEPARATION_M
    left, right = float(odom.state[6]), float(odom.state[7])
    k = start
    if odom.t_ns is None:  # the first reading only starts the filter
        odom.add_wheel_positions(k * STEP_NS, left, right)
    for _ in range(round(seconds * 30)):
        k += 1
        t = k * STEP_NS
        for j in range(6, 0, -1):
            odom.add_gyro(t - j * 5_000_000 + 1, w if gyro is None else gyro)
        left += (v - w * b / 2) / r * STEP_NS * 1e-9
        right += (v + w * b / 2) / r * STEP_NS * 1e-9
        odom.add_wheel_positions(t, left, right)
    return k


@dataclass(frozen=True)
class DriveRun:
    """Filter estimates and ground truth at each filter step."""

    t_ns: NDArray[np.int64]
    state: NDArray[np.float64]  # (N, 8): x, y, yaw (unwrapped), v, yaw_rate, gyro_bias, wheel angles
    covariance: NDArray[np.float64]  # (N, 8, 8)
    truth: NDArray[np.float64]  # (N, 6): the first six states; rates are interval averages
    distance_m: float
    estimates: list[OdometryEstimate]  # what /odom would publish at each step
    native: bool  # the compiled kernel stepped the filter
    slip_detections: int

    def errors(self) -> NDArray[np.float64]:
        err = self.state[:, :6] - self.truth
        err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
        return err

    def final_position_error_m(self) -> float:
        e = self.errors()[-1]
        return float(np.hypot(e[0], e[1]))

    def final_yaw_error_rad(self) -> float:
        return float(abs(self.errors()[-1, 2]))

    def nees(self, dims: tuple[int, ...] = (0, 1, 2)) -> NDArray[np.float64]:
        """NEES at every step after the first (where the filter is exactly at its known start)."""
        idx = np.array(dims)
        err = self.errors()[1:, idx]
        cov = self.covariance[1:, idx[:, None], idx[None, :]]
        return np.einsum("ni,ni->n", err, np.linalg.solve(cov, err[:, :, None])[:, :, 0])


def run_drive(
    traj: Trajectory,
    *,
    config: EstimationSection | None = None,
    disturbances: Disturbances | None = None,
    encoder_spec: EncoderSpec | None = None,
    seed: int = 0,
    native: bool = True,
) -> DriveRun:
    """Run the default TurtleBot3 sensors (with `disturbances`) and the EKF along `traj`.

    The trajectory must already carry any wheel slip of `disturbances` (slip moves the chassis).
    """
    dist = disturbances or Disturbances()
    gyro_ss, accel_ss, enc_ss = np.random.SeedSequence(seed).spawn(3)
    imu = ImuModel(
        dist.imu.apply(ImuSpec()), gyro_rng=np.random.default_rng(gyro_ss), accel_rng=np.random.default_rng(accel_ss)
    )
    spec = encoder_spec or EncoderSpec()
    enc = EncoderModel(spec, dist.encoders, np.random.default_rng(enc_ss))
    ekf = OdometryFilter(
        config or EstimationSection(),
        wheel_radius_m=WHEEL_RADIUS_M,
        wheel_separation_m=WHEEL_SEPARATION_M,
        initial_pose=(float(traj.x_m[0]), float(traj.y_m[0]), float(traj.yaw_rad[0])),
        native=native,
    )
    imu_idx = traj.indices_at_rate(imu.spec.rate_hz).tolist()
    enc_idx = traj.indices_at_rate(spec.rate_hz).tolist()
    t = traj.t_ns.tolist()
    yaw, rate, accel = traj.yaw_rad.tolist(), traj.yaw_rate_radps.tolist(), traj.yaw_accel_radps2.tolist()
    ax, ay = traj.accel_x_mps2.tolist(), traj.accel_y_mps2.tolist()
    left, right = traj.wheel_left_rad.tolist(), traj.wheel_right_rad.tolist()
    steps, states, covs, biases, estimates = [], [], [], [], []
    j = 0
    for i in enc_idx:
        while j < len(imu_idx) and imu_idx[j] <= i:  # IMU samples up to and including this step
            k = imu_idx[j]
            ekf.add_gyro(t[k], imu.sample(yaw[k], rate[k], accel[k], ax[k], ay[k]).angular_velocity_z)
            j += 1
        js = enc.read(t[i], left[i], right[i])
        estimates.append(ekf.add_wheel_positions(t[i], js.position_left_rad, js.position_right_rad))
        steps.append(i)
        states.append(ekf.state)
        covs.append(ekf.covariance)
        biases.append(imu.gyro_bias_radps[2])
    idx = np.array(steps)
    t_ns = traj.t_ns[idx]
    dt = np.diff(t_ns) * 1e-9
    cum_v = np.concatenate(([0.0], np.cumsum(0.5 * (traj.v_mps[1:] + traj.v_mps[:-1])))) * traj.step_ns * 1e-9
    v_avg = np.concatenate(([0.0], np.diff(cum_v[idx]) / dt))
    w_avg = np.concatenate(([0.0], np.diff(traj.yaw_rad[idx]) / dt))
    truth = np.column_stack([traj.x_m[idx], traj.y_m[idx], traj.yaw_rad[idx], v_avg, w_avg, np.array(biases)])
    return DriveRun(
        t_ns, np.array(states), np.array(covs), truth, traj.distance_m, estimates, ekf.native, ekf.slip_detections
    )
