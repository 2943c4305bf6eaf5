"""Cost of the sensors and the odometry EKF per simulated second, at the TurtleBot3's default rates.

Drives the 120 s test trajectory through the IMU model (200 Hz), the wheel encoders (30 Hz), the
EKF's gyro intake (200 Hz) and its predict/update step (30 Hz), timing each call separately. Prints
JSON: CPU milliseconds per simulated second for each part and their share of the whole-run budget
(ARCHITECTURE.md: the default mission, everything included, at most 10 ms per simulated second).
Each part's time is the best of several repeats (least disturbed by other load on the machine).
The EKF step runs in its compiled kernel (the default); the same drive through filterpy's
`SolvedEkf` (the reference path, `native=False`) is timed alongside for the ratio.

    python benchmarks/bench_ekf.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.estimation import EstimationSection, OdometryFilter
from twin.robot.disturbances import Disturbances
from twin.robot.encoders import EncoderModel, EncoderSpec
from twin.robot.imu import ImuModel, ImuSpec
from twin.robot.trajectory import default_test_drive, generate_trajectory

BUDGET_MS_PER_SIM_S = 10.0


def run_once(
    traj_lists: dict[str, list[float]], imu_idx: list[int], enc_idx: list[int], *, native: bool = True
) -> dict[str, float]:
    dist = Disturbances()
    g, a, e = np.random.SeedSequence(0).spawn(3)
    imu = ImuModel(dist.imu.apply(ImuSpec()), gyro_rng=np.random.default_rng(g), accel_rng=np.random.default_rng(a))
    enc = EncoderModel(EncoderSpec(), dist.encoders, np.random.default_rng(e))
    ekf = OdometryFilter(EstimationSection(), wheel_radius_m=0.033, wheel_separation_m=0.287, native=native)
    assert ekf.native == native, "the EKF kernel did not build (no C compiler?)"
    t, yaw, rate = traj_lists["t"], traj_lists["yaw"], traj_lists["rate"]
    acc, ax, ay = traj_lists["accel"], traj_lists["ax"], traj_lists["ay"]
    left, right = traj_lists["left"], traj_lists["right"]
    clock = time.perf_counter
    spent = {"imu_model": 0.0, "encoder_model": 0.0, "ekf_gyro_intake": 0.0, "ekf_step": 0.0}
    j = 0
    for i in enc_idx:
        while j < len(imu_idx) and imu_idx[j] <= i:
            k = imu_idx[j]
            c0 = clock()
            reading = imu.sample(yaw[k], rate[k], acc[k], ax[k], ay[k])
            c1 = clock()
            ekf.add_gyro(t[k], reading.angular_velocity_z)
            c2 = clock()
            spent["imu_model"] += c1 - c0
            spent["ekf_gyro_intake"] += c2 - c1
            j += 1
        c0 = clock()
        js = enc.read(t[i], left[i], right[i])
        c1 = clock()
        ekf.add_wheel_positions(t[i], js.position_left_rad, js.position_right_rad)
        c2 = clock()
        spent["encoder_model"] += c1 - c0
        spent["ekf_step"] += c2 - c1
    return spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5, help="repeats; each part keeps its best")
    args = parser.parse_args()
    traj = generate_trajectory(default_test_drive())
    imu_idx = traj.indices_at_rate(200.0).tolist()
    enc_idx = traj.indices_at_rate(30.0).tolist()
    lists = {
        "t": traj.t_ns.tolist(),
        "yaw": traj.yaw_rad.tolist(),
        "rate": traj.yaw_rate_radps.tolist(),
        "accel": traj.yaw_accel_radps2.tolist(),
        "ax": traj.accel_x_mps2.tolist(),
        "ay": traj.accel_y_mps2.tolist(),
        "left": traj.wheel_left_rad.tolist(),
        "right": traj.wheel_right_rad.tolist(),
    }
    best: dict[str, float] = {}
    reference = float("inf")
    for _ in range(args.repeats):
        for part, seconds in run_once(lists, imu_idx, enc_idx).items():
            best[part] = min(best.get(part, float("inf")), seconds)
        reference = min(reference, run_once(lists, imu_idx, enc_idx, native=False)["ekf_step"])
    sim_s = traj.duration_s
    per_sim_s = {part: 1000.0 * seconds / sim_s for part, seconds in best.items()}
    total = sum(per_sim_s.values())
    a, b = np.random.rand(8, 8), np.random.rand(8, 8)
    matmul_us = min(timeit.repeat(lambda: a @ b, number=20000, repeat=3)) / 20000 * 1e6
    calls = {"imu_model": len(imu_idx), "encoder_model": len(enc_idx), "ekf_gyro_intake": len(imu_idx)}
    calls["ekf_step"] = len(enc_idx)
    result = {
        "benchmark": "ekf",
        "simulated_s": round(sim_s, 3),
        "rates_hz": {"imu": 200, "joint_states_and_ekf": 30},
        "ms_per_simulated_s": {k: round(v, 4) for k, v in per_sim_s.items()},
        "us_per_call": {k: round(1e6 * best[k] / calls[k], 2) for k in best},
        "total_ms_per_simulated_s": round(total, 4),
        "budget_ms_per_simulated_s": BUDGET_MS_PER_SIM_S,
        "share_of_budget": round(total / BUDGET_MS_PER_SIM_S, 4),
        "ekf_only_share_of_budget": round(
            (per_sim_s["ekf_step"] + per_sim_s["ekf_gyro_intake"]) / BUDGET_MS_PER_SIM_S, 4
        ),
        "ekf_step_filterpy_reference": {
            "ms_per_simulated_s": round(1000.0 * reference / sim_s, 4),
            "us_per_call": round(1e6 * reference / len(enc_idx), 2),
            "over_native": round(reference / best["ekf_step"], 1),
        },
        "machine": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "reference_8x8_matmul_us": round(matmul_us, 3),
        },
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
