"""The IMU: what Gazebo classic's `ImuSensor` and the ROS 2 `gazebo_ros_imu_sensor` plugin publish.

Semantics reproduced (gazebo-classic 11 `ImuSensor::UpdateImpl`, gazebo_ros_pkgs `ros2` branch):

- **Angular velocity** is the link's world angular velocity expressed in the IMU frame.
- **Linear acceleration** is the specific force at the IMU's origin, in the IMU frame: the acceleration
  of that point (the chassis acceleration plus the lever-arm terms `alpha x r` and `omega x (omega x r)`)
  minus gravity, so a level IMU at rest reads `+g` on z. Gazebo differentiates the velocity between two
  sensor updates; this model takes the instantaneous accelerations from the chassis, which is the same
  signal without the half-period lag.
- **Orientation** is world-referenced (REP-145): the ROS 2 plugin leaves `initial_orientation_as_reference`
  false, so it reports the IMU frame's rotation in the world, not relative to where it started.
- **Noise** per axis, as Gazebo's `GaussianNoiseModel`: `out = in + bias + N(mean, stddev)`, rounded to
  `precision` for `gaussian_quantized`. The turn-on bias is drawn once from `N(bias_mean, bias_stddev)`
  with a random sign. When `dynamic_bias_stddev` and `dynamic_bias_correlation_time` are set (SDF 1.6+;
  implemented by gz-sensors, ignored by Gazebo classic) the bias also drifts, as gz-sensors does it: a
  first-order Gauss-Markov process driven by white noise of density `dynamic_bias_stddev` (per square
  root second) with correlation time `tau`, advanced exactly over each sample period. Over times much
  shorter than `tau` it is a random walk of `dynamic_bias_stddev` per square-root second; its stationary
  deviation is `dynamic_bias_stddev * sqrt(tau / 2)`. Orientation has no noise.
- **Covariances**: diagonals are the noise variance (`stddev**2`; 0 for `type: none`), the orientation
  covariance is left all zero, as the ROS 2 plugin does.

Noise comes from two caller-owned `numpy.random.Generator` streams (gyro, accelerometer), drawn in
blocks so that one sample costs a few float operations. Same seeds and the same calls give the same
readings.
"""

from __future__ import annotations

import ctypes
import functools
import math
import struct
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from twin.core.clock import period_ns
from twin.core.geometry import quat_from_rpy
from twin.world.robot_model import ImuSpec as SdfImuSpec
from twin.world.robot_model import NoiseSpec

if TYPE_CHECKING:
    from twin.bag import ImuEncoder

__all__ = [
    "GRAVITY_MPS2",
    "GaussianNoise",
    "ImuModel",
    "ImuReading",
    "ImuSpec",
    "three_axes",
]

GRAVITY_MPS2 = 9.8
"""Gazebo's default world gravity magnitude (`<gravity>0 0 -9.8</gravity>`)."""

# Noise samples drawn per refill; a block covers 1.28 s at 200 Hz.
_BLOCK = 256

Vec3 = tuple[float, float, float]

_new_reading = tuple.__new__  # builds the NamedTuple without its keyword-parsing __new__


@dataclass(frozen=True, kw_only=True, slots=True)
class GaussianNoise:
    """One axis of an SDF `<noise>` element, in the unit of its channel (rad/s or m/s²).

    Field names follow SDF so a parsed `<noise>` maps one to one. `dynamic_bias_correlation_time_s`
    is SDF's `dynamic_bias_correlation_time`; 0 disables the drift.
    """

    type: Literal["none", "gaussian", "gaussian_quantized"] = "gaussian"
    mean: float = 0.0
    stddev: float = 0.0
    bias_mean: float = 0.0
    bias_stddev: float = 0.0
    dynamic_bias_stddev: float = 0.0
    dynamic_bias_correlation_time_s: float = 0.0
    precision: float = 0.0

    def __post_init__(self) -> None:
        for name in ("stddev", "bias_stddev", "dynamic_bias_stddev", "dynamic_bias_correlation_time_s", "precision"):
            value = getattr(self, name)
            if not (value >= 0.0 and math.isfinite(value)):
                msg = f"{name} must be a finite number >= 0, got {value}"
                raise ValueError(msg)

    @property
    def variance(self) -> float:
        """The white-noise variance gazebo_ros writes on the covariance diagonal."""
        return 0.0 if self.type == "none" else self.stddev * self.stddev

    @property
    def drifts(self) -> bool:
        """True when the bias drifts (dynamic bias set and enabled)."""
        return self.type != "none" and self.dynamic_bias_stddev > 0.0 and self.dynamic_bias_correlation_time_s > 0.0


def three_axes(noise: GaussianNoise) -> tuple[GaussianNoise, GaussianNoise, GaussianNoise]:
    """Return the same noise for x, y and z (as the TurtleBot3 SDF sets it)."""
    return (noise, noise, noise)


_TB3_GYRO = GaussianNoise(stddev=2e-4)
_TB3_ACCEL = GaussianNoise(stddev=1.7e-2)


@dataclass(frozen=True, kw_only=True, slots=True)
class ImuSpec:
    """Where the IMU sits, how often it samples, and its noise per axis.

    Defaults are the TurtleBot3 Waffle's `tb3_imu` (TB3_FACTS.md §2.2): 200 Hz, frame `imu_link`,
    mounted at (-0.032, 0, 0.068) m in `base_footprint` (SDF `imu_joint`), level.

    Attributes:
        rate_hz: Sample rate.
        frame_id: `header.frame_id` of the readings (the parent link, or the plugin's `frame_name`).
        mount_xyz_m: IMU origin in the chassis frame (`base_footprint`, on the wheel axis), metres.
        mount_rpy_rad: IMU axes relative to the chassis axes (fixed-axis roll, pitch, yaw).
        gravity_mps2: Magnitude of gravity along world -z.
        angular_velocity_noise: Gyro noise for x, y, z (rad/s).
        linear_acceleration_noise: Accelerometer noise for x, y, z (m/s²).
    """

    rate_hz: float = 200.0
    frame_id: str = "imu_link"
    mount_xyz_m: Vec3 = (-0.032, 0.0, 0.068)
    mount_rpy_rad: Vec3 = (0.0, 0.0, 0.0)
    gravity_mps2: float = GRAVITY_MPS2
    angular_velocity_noise: tuple[GaussianNoise, GaussianNoise, GaussianNoise] = field(
        default_factory=lambda: three_axes(_TB3_GYRO)
    )
    linear_acceleration_noise: tuple[GaussianNoise, GaussianNoise, GaussianNoise] = field(
        default_factory=lambda: three_axes(_TB3_ACCEL)
    )

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0.0 and math.isfinite(self.rate_hz)):
            msg = f"rate_hz must be a positive number, got {self.rate_hz}"
            raise ValueError(msg)


class ImuReading(NamedTuple):
    """One `sensor_msgs/Imu` worth of numbers: orientation (x, y, z, w), rad/s, m/s², in the IMU frame."""

    orientation_x: float
    orientation_y: float
    orientation_z: float
    orientation_w: float
    angular_velocity_x: float
    angular_velocity_y: float
    angular_velocity_z: float
    linear_acceleration_x: float
    linear_acceleration_y: float
    linear_acceleration_z: float


def _gauss_markov(
    steps: NDArray[np.float64], phi: float, sigma_d: float, start: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Run `b[n] = phi * b[n-1] + sigma_d * w[n]` down each column of `steps` from `b[-1] = start`.

    The same float operations, in the same order, as a first-order IIR filter in transposed direct
    form (e.g. `scipy.signal.lfilter([sigma_d], [1, -phi], steps, axis=0, zi=phi * start)`), so the
    drift is bit for bit what that call gives; written out because the recursion is one multiply-add
    per sample and `scipy.signal` costs most of a second to import.
    """
    driven = (sigma_d * steps).T.tolist()  # per column: sigma_d * w[n]
    out = np.empty_like(steps)
    for col, (b0, column) in enumerate(zip(start.tolist(), driven, strict=True)):
        z = phi * b0
        for n, sw in enumerate(column):
            b = z + sw
            column[n] = b
            z = phi * b
        out[:, col] = column
    return out


class _ChannelNoise:
    """The additive error of the three axes of one channel, from one random stream, drawn in blocks."""

    def __init__(self, axes: tuple[GaussianNoise, GaussianNoise, GaussianNoise], rng: np.random.Generator, dt_s: float):
        self._rng = rng
        self._mean = np.array([0.0 if a.type == "none" else a.mean for a in axes])
        self._std = np.array([0.0 if a.type == "none" else a.stddev for a in axes])
        self.quantize = tuple(
            (i, a.precision) for i, a in enumerate(axes) if a.type == "gaussian_quantized" and a.precision > 1e-6
        )
        # Turn-on bias, as Gazebo samples it: N(bias_mean, bias_stddev), sign flipped with probability 1/2.
        bias = rng.normal(0.0, 1.0, 3) * [a.bias_stddev for a in axes] + [a.bias_mean for a in axes]
        flip = rng.uniform(0.0, 1.0, 3) < 0.5
        self.bias: NDArray[np.float64] = np.where(flip, -bias, bias) * [a.type != "none" for a in axes]
        # First-order Gauss-Markov drift, exact over one sample period: b' = phi b + sigma_d w, driven by
        # white noise of density dynamic_bias_stddev (as gz-sensors' GaussianNoiseModel).
        self._drift_axes = tuple(i for i, a in enumerate(axes) if a.drifts)
        # Axes with the same drift (usually all three) are filtered in one call: (phi, sigma_d) -> axes.
        groups: dict[tuple[float, float], list[int]] = {}
        for i in self._drift_axes:
            tau, sigma = axes[i].dynamic_bias_correlation_time_s, axes[i].dynamic_bias_stddev
            phi, sigma_d = math.exp(-dt_s / tau), sigma * math.sqrt(-0.5 * tau * math.expm1(-2.0 * dt_s / tau))
            groups.setdefault((phi, sigma_d), []).append(i)
        columns = {axis: col for col, axis in enumerate(self._drift_axes)}  # in the block's drift steps
        self._drift_groups = tuple(
            (phi, sigma_d, axes_, [columns[i] for i in axes_]) for (phi, sigma_d), axes_ in groups.items()
        )

    def block(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Draw the next `_BLOCK` samples: the bias of each, and its total additive error (bias + white)."""
        white = self._rng.standard_normal((_BLOCK, 3)) * self._std + self._mean
        biases = np.repeat(self.bias[None, :], _BLOCK, axis=0)
        if self._drift_axes:
            steps = self._rng.standard_normal((_BLOCK, len(self._drift_axes)))
            for phi, sigma_d, axes, columns in self._drift_groups:
                biases[:, axes] = _gauss_markov(steps[:, columns], phi, sigma_d, self.bias[axes])
            self.bias = biases[-1].copy()
        return biases + self._mean, white + biases


class ImuModel:
    """An IMU on a planar chassis, sampled by the caller at `spec.rate_hz`.

    Args:
        spec: Mounting, rate and noise.
        gyro_rng: The gyro's noise stream.
        accel_rng: The accelerometer's noise stream.
    """

    def __init__(self, spec: ImuSpec, *, gyro_rng: np.random.Generator, accel_rng: np.random.Generator) -> None:
        self.spec = spec
        self.period_ns = period_ns(spec.rate_hz)
        dt_s = self.period_ns * 1e-9
        self._gyro = _ChannelNoise(spec.angular_velocity_noise, gyro_rng, dt_s)
        self._accel = _ChannelNoise(spec.linear_acceleration_noise, accel_rng, dt_s)
        self._quantize = tuple(self._gyro.quantize) + tuple((i + 3, p) for i, p in self._accel.quantize)
        self._rows: list[list[float]] = []  # per sample: gyro x, y, z and accel x, y, z errors
        self._biases: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None  # gyro, accel: per sample
        self._next = _BLOCK
        qx, qy, qz, qw = quat_from_rpy(*spec.mount_rpy_rad)
        r = _rotation(qx, qy, qz, qw)  # IMU axes in chassis axes; readings are R^T times chassis vectors
        rx, ry = float(spec.mount_xyz_m[0]), float(spec.mount_xyz_m[1])
        rot = [float(v) for v in r.ravel()]
        g = spec.gravity_mps2
        gravity = (rot[6] * g, rot[7] * g, rot[8] * g)  # minus gravity in IMU axes (the chassis stays level)
        self._const = (*rot, rx, ry, *gravity, qx, qy, qz, qw)
        self.orientation_covariance: tuple[float, ...] = (0.0,) * 9
        self.angular_velocity_covariance = _diagonal(spec.angular_velocity_noise)
        self.linear_acceleration_covariance = _diagonal(spec.linear_acceleration_noise)
        self._compiled: Any = None  # the C sampler's state (`compiled_sampler`), which then owns the noise index
        self._block = np.zeros((_BLOCK, 6))  # the noise block the C sampler reads

    @property
    def gyro_bias_radps(self) -> Vec3:
        """The gyro's constant error (bias plus noise mean) at the last sample, per axis: ground truth for tests."""
        return self._bias_at_last(0)

    @property
    def accel_bias_mps2(self) -> Vec3:
        """The accelerometer's constant error (bias plus noise mean) at the last sample, per axis."""
        return self._bias_at_last(1)

    def _bias_at_last(self, channel: int) -> Vec3:
        if self._biases is None:
            self._refill()
        assert self._biases is not None
        used = self._next if self._compiled is None else int(self._compiled.next)
        x, y, z = self._biases[channel][max(used - 1, 0)].tolist()
        return (x, y, z)

    def _refill(self) -> None:
        gyro_bias, gyro_error = self._gyro.block()
        accel_bias, accel_error = self._accel.block()
        rows = np.hstack((gyro_error, accel_error))
        self._biases = (gyro_bias, accel_bias)
        if self._compiled is None:
            self._rows = rows.tolist()
            self._next = 0
        else:
            self._block[:] = rows
            self._compiled.next = 0

    def compiled_sampler(
        self, chassis_address: int, initial_yaw_rad: float, encoder: ImuEncoder
    ) -> Callable[[int], tuple[ImuReading, bytes]] | None:
        """Return `ImuNode`'s per-sample path in C, or None where it cannot run (then sample in Python).

        The returned `sample(t_ns)` reads the chassis at `chassis_address` (x, y, yaw, v, yaw rate,
        ax, ay, yaw acceleration: eight doubles, the compiled drive loop's), derives the yaw rate
        from the heading change since the last sample (the chassis' own rate at the first, from
        `initial_yaw_rad` at t = 0), and returns the reading `sample` would give with the message
        `encoder.encode` would make, to the bit. From then on the model is sampled only through the
        latest sampler (a later call takes over the noise stream where it is). None without the
        compiled kernel, on a big-endian machine, or with `gaussian_quantized` axes.
        """
        from twin.robot._native import ImuState, load_imu_kernel

        kernel = load_imu_kernel()
        if kernel is None or self._quantize or sys.byteorder != "little":
            return None
        template = encoder.encode(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        message = (ctypes.c_ubyte * len(template)).from_buffer_copy(template)
        state = ImuState()
        state.chassis = chassis_address
        state.noise = self._block.ctypes.data
        state.message = ctypes.addressof(message)
        state.rows = _BLOCK
        state.stamp_at, state.orientation_at, state.angular_velocity_at, state.linear_acceleration_at = encoder.offsets
        state.last_t_ns = 0
        state.last_yaw = initial_yaw_rad
        state.k[:] = self._const
        if self._compiled is not None:  # an earlier sampler's block: go on where it is
            state.next = self._compiled.next
        elif self._biases is not None:  # sampled in Python before: go on in the same block
            self._block[:] = self._rows
            state.next = self._next
        else:
            state.next = _BLOCK
        self._compiled = state  # a later call takes over from this sampler
        step = functools.partial(kernel.twin_imu_sample, ctypes.byref(state))
        out = memoryview((ctypes.c_ubyte * ctypes.sizeof(state)).from_buffer(state))[ImuState.out.offset :]
        unpack_reading, new, refill = struct.Struct("<10d").unpack_from, tuple.__new__, self._refill
        keep = (message, state)  # the closure owns the buffers the C code points to

        def sample(t_ns: int) -> tuple[ImuReading, bytes]:
            if step(t_ns):  # the noise block is used up
                refill()
                step(t_ns)
            reading: ImuReading = new(ImuReading, unpack_reading(out))
            return reading, bytes(keep[0])

        return sample

    def sample(
        self,
        yaw_rad: float,
        yaw_rate_radps: float,
        yaw_accel_radps2: float,
        accel_x_mps2: float,
        accel_y_mps2: float,
    ) -> ImuReading:
        """Return the next noisy reading of a level chassis.

        Args:
            yaw_rad: Chassis yaw in the world.
            yaw_rate_radps: Chassis yaw rate.
            yaw_accel_radps2: Chassis yaw acceleration.
            accel_x_mps2: Acceleration of the chassis origin along the chassis x axis (longitudinal).
            accel_y_mps2: Acceleration of the chassis origin along the chassis y axis (lateral; v times
                yaw rate for a rolling diff drive).
        """
        i = self._next
        if i == _BLOCK:
            self._refill()
            i = 0
        self._next = i + 1
        n0, n1, n2, n3, n4, n5 = self._rows[i]
        r00, r01, r02, r10, r11, r12, r20, r21, r22, rx, ry, g0, g1, g2, mx, my, mz, mw = self._const
        w = yaw_rate_radps
        # Specific force at the IMU origin in chassis axes: a + alpha x r + w x (w x r) - g.
        w2 = w * w
        fx = accel_x_mps2 - yaw_accel_radps2 * ry - w2 * rx
        fy = accel_y_mps2 + yaw_accel_radps2 * rx - w2 * ry
        # World orientation of the IMU: q_world_chassis (yaw only) times q_chassis_imu.
        s, c = math.sin(0.5 * yaw_rad), math.cos(0.5 * yaw_rad)
        reading: ImuReading = _new_reading(
            ImuReading,
            (
                c * mx - s * my,
                c * my + s * mx,
                c * mz + s * mw,
                c * mw - s * mz,
                r20 * w + n0,
                r21 * w + n1,
                r22 * w + n2,
                r00 * fx + r10 * fy + g0 + n3,
                r01 * fx + r11 * fy + g1 + n4,
                r02 * fx + r12 * fy + g2 + n5,
            ),
        )
        return self._quantized(reading) if self._quantize else reading

    def _quantized(self, reading: ImuReading) -> ImuReading:
        """Round the `gaussian_quantized` axes to their precision (Gazebo's `GaussianNoiseModel`)."""
        out = list(reading)
        for k, precision in self._quantize:
            out[k + 4] = round(out[k + 4] / precision) * precision
        return _new_reading(ImuReading, out)


def _rotation(x: float, y: float, z: float, w: float) -> NDArray[np.float64]:
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _diagonal(axes: tuple[GaussianNoise, GaussianNoise, GaussianNoise]) -> tuple[float, ...]:
    vx, vy, vz = (a.variance for a in axes)
    return (vx, 0.0, 0.0, 0.0, vy, 0.0, 0.0, 0.0, vz)


def _gaussian(noise: NoiseSpec) -> GaussianNoise:
    kind = noise.type if noise.type in ("gaussian", "gaussian_quantized") else "none"
    return GaussianNoise(
        type=kind,  # type: ignore[arg-type]
        mean=noise.mean,
        stddev=noise.stddev,
        bias_mean=noise.bias_mean,
        bias_stddev=noise.bias_stddev,
        dynamic_bias_stddev=noise.dynamic_bias_stddev,
        dynamic_bias_correlation_time_s=noise.dynamic_bias_correlation_time_s,
        precision=noise.precision,
    )


def imu_model_spec(sdf: SdfImuSpec) -> ImuSpec:
    """Return the IMU model's spec for an IMU read from a robot's SDF (rate, frame, mount and noise)."""
    mount = sdf.mount
    return ImuSpec(
        rate_hz=sdf.rate_hz,
        frame_id=sdf.frame_id,
        mount_xyz_m=(mount.x_m, mount.y_m, mount.z_m),
        mount_rpy_rad=(mount.roll_rad, mount.pitch_rad, mount.yaw_rad),
        angular_velocity_noise=(
            _gaussian(sdf.angular_velocity_noise[0]),
            _gaussian(sdf.angular_velocity_noise[1]),
            _gaussian(sdf.angular_velocity_noise[2]),
        ),
        linear_acceleration_noise=(
            _gaussian(sdf.linear_acceleration_noise[0]),
            _gaussian(sdf.linear_acceleration_noise[1]),
            _gaussian(sdf.linear_acceleration_noise[2]),
        ),
    )
