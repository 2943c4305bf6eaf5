"""The IMU node's compiled per-sample path against its Python path: the same readings and messages, to the bit."""

from __future__ import annotations

import ctypes
import math
from typing import Any

import numpy as np
import pytest

from tests.unit.sim.test_executor import FakeSink
from twin.bag import ImuEncoder
from twin.node import Node
from twin.robot._native import load_imu_kernel
from twin.robot.chassis import ChassisState
from twin.robot.imu import GaussianNoise, ImuModel, ImuSpec, three_axes
from twin.robot.nodes import ImuNode
from twin.sim.executor import Executor

PERIOD_NS = 5_000_000


class ImuListener(Node):
    def __init__(self) -> None:
        super().__init__("listener")
        self.heard: list[Any] = []
        self.create_subscription("sensor_msgs/msg/Imu", "/imu", self.heard.append, 10, raw=True)


def _model(spec: ImuSpec, seed: int) -> ImuModel:
    gyro_ss, accel_ss = np.random.SeedSequence(seed).spawn(2)
    return ImuModel(spec, gyro_rng=np.random.default_rng(gyro_ss), accel_rng=np.random.default_rng(accel_ss))


def _run(spec: ImuSpec, chassis: Any, states: np.ndarray, times: list[int], *, compiled: bool) -> tuple[Any, ...]:
    """Publish one sample per (time, chassis state) through an ImuNode; return the recorded bytes and readings."""
    imu = _model(spec, seed=3)
    read = lambda: ChassisState(*chassis[:8], False)  # noqa: E731 - the Python path's chassis reader
    node = ImuNode(imu, read, 0.4, chassis_address=ctypes.addressof(chassis) if compiled else None)
    sink, listener = FakeSink(), ImuListener()
    executor = Executor(1_000_000)
    executor.add_sink(sink)
    executor.add_node(node)
    executor.add_node(listener)
    (task,) = [t for t in executor.scheduler.tasks if t.name == "imu.on_timer"]
    for t_ns, state in zip(times, states, strict=True):
        chassis[:8] = state.tolist()
        executor.now_ns = t_ns
        task.fn(t_ns)
    return [w[2] for w in sink.writes], [m.data for m in listener.heard], imu.gyro_bias_radps, imu.accel_bias_mps2


@pytest.mark.parametrize(
    "spec",
    [
        ImuSpec(),  # the TurtleBot3's
        ImuSpec(
            mount_xyz_m=(0.05, -0.02, 0.1),
            mount_rpy_rad=(0.1, -0.2, 2.5),
            angular_velocity_noise=three_axes(GaussianNoise(stddev=1e-3, bias_mean=1e-3, bias_stddev=1e-3)),
            linear_acceleration_noise=three_axes(
                GaussianNoise(stddev=0.05, dynamic_bias_stddev=0.01, dynamic_bias_correlation_time_s=30.0)
            ),
        ),
    ],
    ids=["tb3", "tilted_drifting"],
)
def test_the_compiled_sample_is_the_python_sample_to_the_bit(spec: ImuSpec) -> None:
    if load_imu_kernel() is None:
        pytest.fail("the IMU kernel did not build (no C compiler?); this test compares it with the Python path")
    rng = np.random.default_rng(11)
    n = 700  # past two noise blocks of 256
    states = rng.normal(size=(n, 8)) * [1, 1, 4, 0.3, 2, 1, 1, 5]
    times = [0, 0, *[k * PERIOD_NS for k in range(1, n - 1)]]  # a repeated time: the chassis' own yaw rate
    chassis = (ctypes.c_double * 8)()
    python = _run(spec, chassis, states, times, compiled=False)
    compiled = _run(spec, chassis, states, times, compiled=True)
    assert len(python[0]) == n
    assert compiled[0] == python[0]  # the recorded messages
    assert [repr(r) for r in compiled[1]] == [repr(r) for r in python[1]]  # what subscribers read
    assert compiled[2:] == python[2:]  # the noise stream where it stands
    assert len({r[1].angular_velocity_z for r in python[1]}) == n  # every sample its own numbers


def test_quantized_axes_keep_the_python_path() -> None:
    spec = ImuSpec(
        angular_velocity_noise=three_axes(GaussianNoise(type="gaussian_quantized", stddev=1e-3, precision=1e-3))
    )
    imu = _model(spec, seed=0)
    chassis = (ctypes.c_double * 8)()
    assert imu.compiled_sampler(ctypes.addressof(chassis), 0.0, ImuEncoder()) is None
    assert math.isfinite(imu.sample(0.0, 0.0, 0.0, 0.0, 0.0).angular_velocity_z)
