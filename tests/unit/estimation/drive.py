"""Drive the sensor models and the EKF along a ground-truth trajectory (the loop, until the lead's runs it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.estimation import EstimationSection, OdometryFilter
from twin.robot.disturbances import Disturbances
from twin.robot.encoders import EncoderModel, EncoderSpec
from twin.robot.imu import ImuModel, ImuSpec
from twin.robot.trajectory import Trajectory

WHEEL_RADIUS_M = 0.033
WHEEL_SEPARATION_M = 0.287


@dataclass(frozen=True)
class DriveRun:
    """Filter estimates and ground truth at each filter step."""

    t_ns: NDArray[np.int64]
    state: NDArray[np.float64]  # (N, 6): x, y, yaw (unwrapped), v, yaw_rate, gyro_bias
    covariance: NDArray[np.float64]  # (N, 6, 6)
    truth: NDArray[np.float64]  # (N, 6): same layout; rates are interval averages
    distance_m: float

    def errors(self) -> NDArray[np.float64]:
        err = self.state - self.truth
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
    )
    imu_idx = traj.indices_at_rate(imu.spec.rate_hz).tolist()
    enc_idx = traj.indices_at_rate(spec.rate_hz).tolist()
    t = traj.t_ns.tolist()
    yaw, rate, accel = traj.yaw_rad.tolist(), traj.yaw_rate_radps.tolist(), traj.yaw_accel_radps2.tolist()
    ax, ay = traj.accel_x_mps2.tolist(), traj.accel_y_mps2.tolist()
    left, right = traj.wheel_left_rad.tolist(), traj.wheel_right_rad.tolist()
    steps, states, covs, biases = [], [], [], []
    j = 0
    for i in enc_idx:
        while j < len(imu_idx) and imu_idx[j] <= i:  # IMU samples up to and including this step
            k = imu_idx[j]
            ekf.add_gyro(t[k], imu.sample(yaw[k], rate[k], accel[k], ax[k], ay[k]).angular_velocity_z)
            j += 1
        js = enc.read(t[i], left[i], right[i])
        ekf.add_wheel_positions(t[i], js.position_left_rad, js.position_right_rad)
        steps.append(i)
        states.append(ekf.ekf.x[:6].copy())
        covs.append(ekf.ekf.P[:6, :6].copy())
        biases.append(imu.gyro_bias_radps[2])
    idx = np.array(steps)
    t_ns = traj.t_ns[idx]
    dt = np.diff(t_ns) * 1e-9
    cum_v = np.concatenate(([0.0], np.cumsum(0.5 * (traj.v_mps[1:] + traj.v_mps[:-1])))) * traj.step_ns * 1e-9
    v_avg = np.concatenate(([0.0], np.diff(cum_v[idx]) / dt))
    w_avg = np.concatenate(([0.0], np.diff(traj.yaw_rad[idx]) / dt))
    truth = np.column_stack([traj.x_m[idx], traj.y_m[idx], traj.yaw_rad[idx], v_avg, w_avg, np.array(biases)])
    return DriveRun(t_ns, np.array(states), np.array(covs), truth, traj.distance_m)
