"""Drivetrain cost per simulated second at 1 ms steps, two wheels: FMU stepping through the low-level
and the convenience API, the chassis coupling alone, and the whole FMU drivetrain, with its step loop
compiled (`native`) and in Python (`lowlevel`, `convenience`). Prints JSON.

The drivetrain is advanced in batches of 5 steps, as the simulation loop does between its events
(IMU at 200 Hz), on open floor: the contact check says free and the free distance is 10 m.
`native_one_call` runs the whole measurement in one `advance`: the compiled loop's own cost.
`velocity-servo_lowlevel_isolated` runs the FMUs in a child process (`drive: {isolation: process}`);
`isolation_overhead_us_per_wheel_step` is its wall time over the same Python loop in-process, per
wheel per step (`--isolation-only` measures just these two).

    python benchmarks/bench_drivetrain.py [--seconds 5] [--fmi 2|3] [--isolation-only]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.cosim.build import resolve_fmu
from twin.cosim.fmu import FmuFile
from twin.cosim.step_group import StepGroup
from twin.robot.chassis import Chassis, ChassisParams
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import FmuDrivetrain

STEP_S = 0.001


def _best(fn, repeats: int = 3, min_total_s: float = 0.5) -> float:
    """The fastest of at least `repeats` runs, repeated until `min_total_s` has passed (short runs on
    a shared machine need many tries for a clean minimum)."""
    best, total, n = float("inf"), 0.0, 0
    while n < repeats or total < min_total_s:
        t0 = time.perf_counter()
        fn()
        took = time.perf_counter() - t0
        best, total, n = min(best, took), total + took, n + 1
    return best


def fmu_only(path: Path, api: str, steps: int) -> float:
    with FmuFile(path) as fmu:
        v = fmu.info.variables
        ins = [v["voltage"].value_reference, v["load_torque"].value_reference]
        outs = [v[n].value_reference for n in ("wheel_speed", "wheel_angle", "current", "motor_torque")]
        kind = "lowlevel" if api == "shim" else api
        left = fmu.instantiate("left", step_s=STEP_S, inputs=ins, outputs=outs, api=kind)
        right = fmu.instantiate("right", step_s=STEP_S, inputs=ins, outputs=outs, api=kind)
        left.inputs[0] = right.inputs[0] = 6.0
        if api == "shim":
            group = StepGroup((left, right), step_s=STEP_S)
            assert group.compiled

            def run() -> None:
                step_next = group.step_next
                for _ in range(steps):
                    if step_next() >= 0:
                        raise RuntimeError("FMU failed")

        else:

            def run() -> None:
                for k in range(steps):
                    left.step(k * STEP_S)
                    right.step(k * STEP_S)

        return _best(run)


def chassis_only(steps: int) -> float:
    chassis = Chassis(
        ChassisParams.tb3_waffle(), step_s=STEP_S, wheel_inertia_kgm2=4.5e-3, contact=lambda x, y, a: False
    )

    def run() -> None:
        for k in range(steps):
            chassis.update(5.0 + 1e-4 * k, 5.1)

    return _best(run)


def drivetrain(fmi: int, api: str, profile: str, steps: int, batch: int = 5, isolation: str = "none") -> float:
    fmu = "builtin:xm430_w210" if profile == "voltage" else "builtin:xm430_w210_servo"
    drive = FmuDrive(fmu=fmu, fmi_version=fmi, profile=profile, api=api, isolation=isolation)  # type: ignore[arg-type]
    with FmuDrivetrain(
        drive,
        ChassisParams.tb3_waffle(),
        step_ns=1_000_000,
        contact=lambda x, y, a: False,
        free_distance=lambda x, y, a: 10.0,
        bounding_radius_m=0.3,
    ) as dt:
        assert dt.native == (api == "native" and isolation == "none")
        dt.set_cmd_vel(0.2, 0.3)

        def run() -> None:
            for _ in range(steps // batch):
                dt.advance(batch)

        return _best(run)


def isolation_cost(fmi: int, steps: int, per_s: float) -> dict[str, object]:
    """The velocity-servo drive's Python loop with the FMUs in-process and in a child process."""
    in_process = drivetrain(fmi, "lowlevel", "velocity-servo", steps) * per_s
    isolated = drivetrain(fmi, "lowlevel", "velocity-servo", steps, isolation="process") * per_s
    return {
        "ms_wall_per_sim_s_isolation": {
            "velocity-servo_lowlevel": round(in_process, 3),
            "velocity-servo_lowlevel_isolated": round(isolated, 3),
        },
        # ms per simulated second at 1 ms steps = µs per step; two wheels per step.
        "isolation_overhead_us_per_wheel_step": round((isolated - in_process) / 2.0, 3),
        "isolated_over_in_process": round(isolated / in_process, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per measurement")
    parser.add_argument("--fmi", type=int, choices=(2, 3), default=2)
    parser.add_argument("--isolation-only", action="store_true", help="measure only the isolated drive's overhead")
    args = parser.parse_args()
    steps = round(args.seconds / STEP_S)
    isolated = isolation_cost(args.fmi, steps, 1e3 / args.seconds)
    if args.isolation_only:
        print(json.dumps({"benchmark": "drivetrain_isolation", "fmi_version": args.fmi, **isolated}, indent=2))
        return
    path = resolve_fmu("builtin:xm430_w210", fmi_version=args.fmi)
    per_s = 1e3 / args.seconds  # seconds measured → ms per simulated second
    shim = fmu_only(path, "shim", steps) * per_s
    low = fmu_only(path, "lowlevel", steps) * per_s
    conv = fmu_only(path, "convenience", steps) * per_s
    chassis = chassis_only(steps) * per_s
    whole = {
        f"{profile}_{api}": drivetrain(args.fmi, api, profile, steps) * per_s
        for profile in ("voltage", "velocity-servo")
        for api in ("native", "lowlevel", "convenience")
    }
    for profile in ("voltage", "velocity-servo"):
        whole[f"{profile}_native_one_call"] = drivetrain(args.fmi, "native", profile, steps, batch=steps) * per_s
    result = {
        "benchmark": "drivetrain",
        "python": platform.python_version(),
        "machine": platform.machine(),
        "fmi_version": args.fmi,
        "step_s": STEP_S,
        "wheels": 2,
        "simulated_s": args.seconds,
        "ms_cpu_per_sim_s": {
            "fmu_lowlevel_shim": round(shim, 3),
            "fmu_lowlevel": round(low, 3),
            "fmu_convenience": round(conv, 3),
            "chassis_coupling": round(chassis, 3),
            **{f"drivetrain_{k}": round(v, 3) for k, v in whole.items()},
        },
        # 1 ms of CPU per simulated second = 1 µs per step; each step is 2 instances x 3 FMI calls.
        "us_per_fmi_call": {
            "lowlevel_shim": round(shim / 6.0, 3),
            "lowlevel": round(low / 6.0, 3),
            "convenience": round(conv / 6.0, 3),
        },
        "ratios": {
            "convenience_over_lowlevel": round(conv / low, 2),
            "lowlevel_over_shim": round(low / shim, 2),
            "chassis_share_of_drivetrain_lowlevel": round(chassis / whole["voltage_lowlevel"], 2),
            "lowlevel_over_native_voltage": round(whole["voltage_lowlevel"] / whole["voltage_native"], 1),
            "lowlevel_over_native_velocity_servo": round(
                whole["velocity-servo_lowlevel"] / whole["velocity-servo_native"], 1
            ),
        },
        **isolated,
        "real_time_factor_drivetrain_voltage_native": round(1e3 / whole["voltage_native"], 1),
        "real_time_factor_drivetrain_voltage_lowlevel": round(1e3 / whole["voltage_lowlevel"], 1),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
