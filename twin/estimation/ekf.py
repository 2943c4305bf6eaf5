"""The odometry EKF: wheel encoders and a gyro fused into a planar pose, twist and their covariances.

State `s = [x, y, yaw, v, yaw_rate, gyro_bias, wheel_left, wheel_right]` (m, m, rad, m/s, rad/s, rad/s,
rad, rad), in the `odom` frame.

**Fusion schedule.** The filter steps once per wheel-encoder reading (30 Hz in the twin, about 20 Hz on a
real TurtleBot3). Gyro samples (200 Hz) are only integrated as they arrive (`add_gyro`: the trapezoid rule
between samples, O(1), no matrix work); at the next encoder reading the integral over the interval (its
tail past the last sample extrapolated from the last two samples and handed to the next interval, so
nothing is lost or counted twice) divided by the interval is one measurement of the average yaw rate,
with variance `sigma**2 / n` for `n` samples. One step is one predict and one stacked update of three
rows. `/odom` is published from the estimate after each step, stamped with the encoder time.

**Model.** Encoder increments and the gyro mean both describe the *average* motion over the interval, so
`v` and `yaw_rate` are the interval's average rates: their random walk is applied first, then the pose and
the wheel angles advance with the new rates (midpoint rule, as the TurtleBot3 firmware's odometry)::

    v' = v + w_v,   r' = r + w_r,   b' = b + w_b
    yaw' = yaw + r' dt,   x' = x + v' dt cos(yaw + r' dt / 2),   y' = y + v' dt sin(yaw + r' dt / 2)
    wheel_left'  = wheel_left  + (v' - r' B / 2) dt / R + n_left
    wheel_right' = wheel_right + (v' + r' B / 2) dt / R + n_right

where `n` is odometry noise whose variance grows with the wheel's travel. The rate noise reaches the
pose and the wheels through the rates' Jacobian columns (`P' = F (P + Q_w) F^T + Q_odometry`).

**Measurements.** The encoders measure the wheel angles, so their rounding is a bounded error of
`tick**2 / 12` per reading, not a random walk; `v` and `yaw_rate` are updated from the wheel travel
through the radius `R` and the separation `B`. The gyro measures `yaw_rate + gyro_bias`. Which rows a
step uses depends on what the wheels did:

- *Moving, gyro fused*: the gyro owns the yaw. Turning wheels may slip, and a slip that lasts would
  otherwise be taken for gyro bias, so the wheels' differential travel is set free for the step: the
  wheels give the speed (their common travel), the gyro the yaw rate.
- *Standstill* (no tick on either wheel for two readings): a zero-velocity update, `v = 0` and
  `yaw_rate = 0`, with the gyro: this is where the gyro bias is learned, where no wheel can slip.
- *Gyro not fused* (or no sample in the interval): the wheels give both speed and yaw rate.
- *Speeds only* (a joint state without positions, `add_wheel_speeds`): the same, from the wheel speeds.

**Gate.** If the normalised innovation squared of an update exceeds the configured chi-square quantile,
the wheels and the gyro disagree beyond their noise (at standstill: the robot turned while its wheels
did not): the wheels' say on the yaw is dropped for that step and the update is redone.

**Numerics.** filterpy's `ExtendedKalmanFilter` computes the gain with `inv` and copies its inputs. The
subclass here keeps its interface and attributes but solves for the gain (Cholesky, `dposv`), applies the
Joseph form as symmetric rank-k updates of P's upper triangle (its `K S K^T` term a Gram matrix) and
mirrors it, calling BLAS/LAPACK directly on Fortran-ordered arrays.

**Speed.** `OdometryFilter` steps through a compiled kernel (`twin.estimation._native`) that does the same
arithmetic in C, a few microseconds per step instead of ~50; `SolvedEkf` is the reference it is tested
against and the fallback without a C compiler (or with `native=False`, `TWIN_NO_NATIVE=1`).
"""

from __future__ import annotations

import ctypes
import functools
import logging
import math
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from twin.core.errors import EstimationError
from twin.estimation._native import LAYOUT_NAMES, load_ekf_kernel
from twin.estimation.config import EstimationSection
from twin.estimation.state import N_STATE, NOT_POSITIVE_DEFINITE, FloatArray

# `SolvedEkf` is here too, loaded on first use (module `__getattr__`); its home is twin.estimation.solved.
__all__ = ["UNOBSERVED_VARIANCE", "OdometryEstimate", "OdometryFilter"]

_log = logging.getLogger(__name__)

UNOBSERVED_VARIANCE = 1e12
"""Variance published for what a planar filter does not estimate (z, roll, pitch; vy, vz, wx, wy),
as `gazebo_ros_diff_drive` does."""

# Variance added to the differential wheel travel when the slip gate fires (rad², i.e. unknown).
_SLIP_RELEASE_RAD2 = 1e4


def _gather(state: tuple[int, ...], ros: tuple[int, ...], unobserved: tuple[int, ...]) -> NDArray[np.intp]:
    """Indices into `[P.ravel(), 0, UNOBSERVED_VARIANCE]` that build a ROS 6x6 covariance (row-major)."""
    out = np.full(36, N_STATE * N_STATE)  # zero
    out[[i * 7 for i in unobserved]] = N_STATE * N_STATE + 1
    for a, ra in zip(state, ros, strict=True):
        for b, rb in zip(state, ros, strict=True):
            out[ra * 6 + rb] = a * N_STATE + b
    return out


# ROS order (x, y, z, rot X, rot Y, rot Z): the pose uses x, y, yaw; the twist v (x) and yaw rate (rot Z).
_POSE_GATHER = _gather((0, 1, 2), (0, 1, 5), unobserved=(2, 3, 4))
_TWIST_GATHER = _gather((3, 4), (0, 5), unobserved=(1, 2, 3, 4))
_BOTH_GATHER = np.concatenate((_POSE_GATHER, _TWIST_GATHER))
_new_estimate = tuple.__new__  # builds the NamedTuple without its keyword-parsing __new__
_RELEASE = _SLIP_RELEASE_RAD2 * np.array([[1.0, -1.0], [-1.0, 1.0]])
_ANGLES, _SPEEDS, _STILL = 0, 1, 2  # what the wheel rows measure (the kernel's kinds)
_COVARIANCE_ROWS = 256  # published covariances allocated at once (the kernel writes one row per step)


class OdometryEstimate(NamedTuple):
    """What `/odom` (nav_msgs/Odometry, `odom` -> `base_footprint`) carries, at `t_ns`.

    Covariances are flat row-major 6x6 in ROS order (x, y, z, rot X, rot Y, rot Z); the twist is in
    the child frame (`base_footprint`). Each estimate owns its arrays.
    """

    t_ns: int
    x_m: float
    y_m: float
    yaw_rad: float
    v_mps: float
    yaw_rate_radps: float
    gyro_bias_radps: float
    pose_covariance: FloatArray
    twist_covariance: FloatArray


def __getattr__(name: str) -> Any:
    """Load `SolvedEkf` (filterpy) on first use."""
    if name == "SolvedEkf":
        return _solved_ekf()
    msg = f"module {__name__!r} has no attribute {name!r}"
    raise AttributeError(msg)


def _solved_ekf() -> Any:
    from twin.estimation.solved import SolvedEkf

    return SolvedEkf


class _KernelState:
    """What the compiled kernel needs of `SolvedEkf` (its state, covariance and noise settings)."""

    def __init__(self, x0: FloatArray, p0: FloatArray) -> None:
        self.x = np.array(x0, dtype=float)
        self.P = np.array(p0, dtype=float, order="F")
        self.rate_variances = (0.0, 0.0, 0.0)
        self.slip_variance_per_rad = 0.0


# chi2(3).ppf(p) = 2 * gammaincinv(1.5, p), as scipy computes it, for the packaged default and the
# usual gate probabilities: scipy.special takes a few hundred ms to import, paid only for others.
_CHI2_3_QUANTILES = {
    0.9: 6.251388631170325,
    0.95: 7.814727903251179,
    0.99: 11.344866730144373,
    0.995: 12.838156466598647,
    0.999: 16.26623619623813,
    0.9999: 21.107513466160444,
}


def chi2_3_quantile(p: float) -> float:
    """Return the chi-square quantile with 3 degrees of freedom (`scipy.stats.chi2(3).ppf(p)`)."""
    known = _CHI2_3_QUANTILES.get(p)
    if known is not None:
        return known
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(1.5, p))


class OdometryFilter:
    """Wheel-encoder and gyro odometry for a differential drive (see the module docstring).

    Per rate: `add_gyro(t_ns, yaw_rate_radps)` for every IMU sample; `add_wheel_positions(t_ns, left_rad,
    right_rad)` for every joint state, which steps the filter and returns the estimate to publish.

    The filter is filterpy's (`SolvedEkf`, in `ekf`). By default each step runs in a compiled kernel
    (`twin.estimation._native`: the same predict, update, gate and slip handling in C, about ten times
    faster); `native=False`, `TWIN_NO_NATIVE=1` or a machine without a C compiler step through `SolvedEkf`
    itself, the reference implementation. Both give the same estimates and covariances to rounding (the
    tests compare them). With the kernel, `ekf.x` and `ekf.P` are views of its workspace: read them, but
    step the filter only through this class.

    Args:
        config: The scenario's `estimation:` section.
        wheel_radius_m: Wheel radius.
        wheel_separation_m: Distance between the wheels.
        initial_pose: Start (x_m, y_m, yaw_rad) in the `odom` frame.
        gyro_samples: `instantaneous` rates (Gazebo, most drivers) are integrated by the trapezoid rule;
            `interval_mean` rates (a gyro reporting its mean over each sample period, as the twin's IMU)
            by the rectangle rule.
        native: Step with the compiled kernel when it is available.

    Raises:
        EstimationError: If the wheel geometry is not positive.
    """

    def __init__(
        self,
        config: EstimationSection,
        *,
        wheel_radius_m: float,
        wheel_separation_m: float,
        initial_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
        gyro_samples: Literal["instantaneous", "interval_mean"] = "instantaneous",
        native: bool = True,
    ) -> None:
        if not (wheel_radius_m > 0.0 and wheel_separation_m > 0.0):
            msg = f"wheel radius and separation must be positive, got {wheel_radius_m} m and {wheel_separation_m} m"
            raise EstimationError(msg)
        self.config = config
        # Instantaneous rates integrate by the trapezoid rule; a gyro that reports its mean rate over
        # each sample period by the rectangle rule, which then gives the heading change exactly.
        self._gyro_mean = gyro_samples == "interval_mean"
        noise = config.measurement_noise
        tick = 2.0 * math.pi / noise.encoder_ticks_per_rev
        self._angle_var = tick * tick / 12.0  # one reading rounded to a tick: uniform error
        self._tick_var = tick * tick
        self._half_tick = 0.5 * tick
        self._last_angles: tuple[float, float] | None = None
        init = config.initial_std
        p0 = np.diag(
            [
                init.position_m**2,
                init.position_m**2,
                init.yaw_rad**2,
                init.velocity_mps**2,
                init.yaw_rate_radps**2,
                init.gyro_bias_radps**2,
                self._angle_var,
                self._angle_var,
            ]
        )
        x0 = np.array([*initial_pose, 0.0, 0.0, 0.0, 0.0, 0.0])
        geometry = {"wheel_radius_m": wheel_radius_m, "wheel_separation_m": wheel_separation_m}
        kernel = load_ekf_kernel() if native else None
        # filterpy (and scipy.stats with it, about a second) loads only for the reference path.
        self.ekf: Any = _KernelState(x0, p0) if kernel is not None else _solved_ekf()(x0, p0, **geometry)
        q = config.process_noise
        self.ekf.rate_variances = (
            q.velocity_random_walk_mps_per_sqrt_s**2,
            q.yaw_rate_random_walk_radps_per_sqrt_s**2,
            q.gyro_bias_random_walk_radps_per_sqrt_s**2,
        )
        self.ekf.slip_variance_per_rad = q.wheel_travel_std_per_sqrt_rad**2
        self._speed_var = noise.wheel_speed_std_radps**2
        self._gyro_var = noise.gyro_std_radps**2
        self._fuse_gyro = config.fuse_gyro
        p_gate = config.slip_gate_probability
        self._gate = chi2_3_quantile(p_gate) if p_gate is not None else None
        inv_r, half_b = 1.0 / wheel_radius_m, 0.5 * wheel_separation_m / wheel_radius_m
        # Measurement rows by kind (_ANGLES, _SPEEDS, _STILL); the third row is the gyro.
        self._h = (
            _rows(N_STATE, [{6: 1.0}, {7: 1.0}, {4: 1.0, 5: 1.0}]),
            _rows(N_STATE, [{3: inv_r, 4: -half_b}, {3: inv_r, 4: half_b}, {4: 1.0, 5: 1.0}]),
            _rows(N_STATE, [{3: 1.0}, {4: 1.0}, {4: 1.0, 5: 1.0}]),
        )
        self._wheel_rows = tuple(np.asfortranarray(h[:2]) for h in self._h)
        self._sparse = tuple([[(j, float(c)) for j, c in enumerate(row) if c] for row in h.tolist()] for h in self._h)
        self._still_var = (noise.standstill_speed_std_mps**2, noise.standstill_yaw_rate_std_radps**2)
        self._still_intervals = 0
        self._z = np.zeros(3)
        self._r3 = np.zeros((3, 3))
        self._gyro_integral_rad = 0.0  # trapezoid integral of the gyro up to its last sample
        self._gyro_last: tuple[int, float] | None = None  # (t_ns, rad/s) of the last sample
        self._gyro_slope = 0.0  # rad/s per ns between the last two samples
        self._gyro_anchor_rad: float | None = None  # the integral's value at the last step time
        self._gyro_count = 0
        self._t_ns: int | None = None
        self.slip_detections = 0
        self._padded = np.zeros(N_STATE * N_STATE + 2)
        self._padded[-1] = UNOBSERVED_VARIANCE
        self.native = kernel is not None
        """True when the compiled kernel steps the filter."""
        # One step, `(t_ns, kind, moving, z_left, z_right, variance) -> estimate`: chosen once.
        self._step: Callable[[int, int, bool, float, float, float], OdometryEstimate] = self._step_filterpy
        if kernel is not None:
            self._bind_kernel(kernel, inv_r=1.0 / wheel_radius_m, half_b=0.5 * wheel_separation_m)
            self._step = self._step_native
        self._estimate = self._make_estimate(0)

    def _bind_kernel(self, kernel: ctypes.CDLL, *, inv_r: float, half_b: float) -> None:
        """Move the state into the kernel's workspace (`ekf.x` and `ekf.P` become views of it)."""
        offsets = (ctypes.c_long * len(LAYOUT_NAMES))()
        kernel.twin_ekf_layout(offsets)
        at = dict(zip(LAYOUT_NAMES, offsets, strict=True))
        ws_c = (ctypes.c_double * at["SIZE"])()
        ws = np.frombuffer(ws_c, dtype=np.float64)
        ekf = self.ekf
        x = ws[at["X"] : at["X"] + N_STATE]
        p = ws[at["P"] : at["P"] + N_STATE * N_STATE].reshape(N_STATE, N_STATE)
        x[:], p[:] = ekf.x, ekf.P
        ws[at["PAD"] : at["PAD"] + 2] = (0.0, UNOBSERVED_VARIANCE)
        gate = -1.0 if self._gate is None else self._gate
        parameters = (
            inv_r,
            half_b,
            *ekf.rate_variances,
            ekf.slip_variance_per_rad,
            _SLIP_RELEASE_RAD2,
            gate,
            float(self._fuse_gyro),
            self._gyro_var,
            *self._still_var,
        )
        ws[at["PAR"] : at["PAR"] + len(parameters)] = parameters
        h = np.concatenate([rows.ravel(order="C") for rows in self._h])
        ws[at["H"] : at["H"] + h.size] = h
        ekf.x, ekf.P = x, p
        ws[at["GATHER"] : at["GATHER"] + _BOTH_GATHER.size] = _BOTH_GATHER
        self._ws_c = ws_c  # owns the memory of the views
        self._kernel = kernel
        self._in, self._in_end = at["IN"], at["IN"] + 9
        self._out = ws[at["OUT"] : at["OUT"] + 6]
        self._new_covariance_block()

    def _new_covariance_block(self) -> None:
        """Give the kernel fresh rows to write the published covariances into, one row per step.

        Each estimate's covariances are views of their own row, which nothing writes again: the
        estimate owns them without a copy per step.
        """
        block = np.empty((_COVARIANCE_ROWS, 72))
        self._poses, self._twists = list(block[:, :36]), list(block[:, 36:])
        self._row = 0
        self._kernel_step = functools.partial(
            self._kernel.twin_ekf_step, self._ws_c, ctypes.c_void_p(block.ctypes.data)
        )
        self._block = block

    @property
    def t_ns(self) -> int | None:
        """Time of the last step (None before the first wheel reading)."""
        return self._t_ns

    @property
    def estimate(self) -> OdometryEstimate:
        """The latest estimate."""
        return self._estimate

    @property
    def state(self) -> FloatArray:
        """A copy of the state (see `twin.estimation.state.STATE_NAMES`; yaw not wrapped)."""
        state: FloatArray = self.ekf.x.copy()
        return state

    @property
    def covariance(self) -> FloatArray:
        """A copy of the 8x8 state covariance."""
        covariance: FloatArray = self.ekf.P.copy()
        return covariance

    def add_gyro(self, t_ns: int, yaw_rate_radps: float) -> None:
        """Integrate one gyro sample (z axis of a level IMU); it is fused at the next wheel reading.

        Samples not after the previous one, and samples that are not a finite number, are ignored.
        """
        last = self._gyro_last
        if last is None:
            if not math.isfinite(yaw_rate_radps):
                return
            if self._t_ns is not None:  # hold the first sample back to the last step
                self._gyro_anchor_rad = -yaw_rate_radps * (t_ns - self._t_ns) * 1e-9
        else:
            dt_ns = t_ns - last[0]
            if dt_ns <= 0 or not math.isfinite(yaw_rate_radps):
                return
            if self._gyro_mean:
                self._gyro_integral_rad += yaw_rate_radps * dt_ns * 1e-9
            else:
                self._gyro_integral_rad += 0.5 * (yaw_rate_radps + last[1]) * dt_ns * 1e-9
                self._gyro_slope = (yaw_rate_radps - last[1]) / dt_ns
        self._gyro_last = (t_ns, yaw_rate_radps)
        self._gyro_count += 1

    def add_wheel_positions(self, t_ns: int, left_rad: float, right_rad: float) -> OdometryEstimate:
        """Step the filter with the wheels' joint positions at `t_ns` and return the new estimate.

        The first reading starts the filter (time and wheel angles) and returns the initial estimate.

        Raises:
            EstimationError: If `t_ns` is not after the previous reading, or a reading is not finite.
        """
        if not (math.isfinite(left_rad) and math.isfinite(right_rad)):
            raise EstimationError(_not_finite(t_ns, left_rad, right_rad))
        last = self._last_angles
        self._last_angles = (left_rad, right_rad)
        if self._t_ns is None or last is None:
            self.ekf.x[6], self.ekf.x[7] = left_rad, right_rad
            return self._start(t_ns)
        half_tick = self._half_tick
        moving = abs(left_rad - last[0]) > half_tick or abs(right_rad - last[1]) > half_tick
        var = self._angle_var
        return self._step(t_ns, _ANGLES, moving, left_rad, right_rad, var)

    def add_wheel_speeds(self, t_ns: int, left_radps: float, right_radps: float) -> OdometryEstimate:
        """Step the filter with the wheels' average speeds since the previous reading.

        For joint states without positions. Each speed has the variance of
        `wheel_speed_std_radps` plus one tick over the interval.

        Raises:
            EstimationError: If `t_ns` is not after the previous reading, or a reading is not finite.
        """
        if not (math.isfinite(left_radps) and math.isfinite(right_radps)):
            raise EstimationError(_not_finite(t_ns, left_radps, right_radps))
        if self._t_ns is None:
            return self._start(t_ns)
        dt = self._dt(t_ns, self._t_ns)
        moving = max(abs(left_radps), abs(right_radps)) * dt > self._half_tick
        var = self._speed_var + self._tick_var / (dt * dt)
        return self._step(t_ns, _SPEEDS, moving, left_radps, right_radps, var)

    def _start(self, t_ns: int) -> OdometryEstimate:
        self._t_ns = t_ns
        self._gyro_anchor_rad = self._gyro_mark(t_ns)
        self._gyro_count = 0
        self._estimate = self._make_estimate(t_ns)
        return self._estimate

    def _dt(self, t_ns: int, last: int) -> float:
        if t_ns <= last:
            msg = f"wheel reading at t={t_ns} ns is not after the previous one at t={last} ns"
            raise EstimationError(msg)
        return (t_ns - last) * 1e-9

    def _gyro_mark(self, t_ns: int) -> float | None:
        """Return the gyro integral at `t_ns`, extrapolated past the last sample (None before any sample)."""
        last = self._gyro_last
        if last is None:
            return None
        tail_ns = t_ns - last[0]
        return self._gyro_integral_rad + (last[1] + 0.5 * self._gyro_slope * tail_ns) * tail_ns * 1e-9

    def _step_filterpy(  # noqa: PLR0917 - the hot path takes plain numbers positionally
        self, t_ns: int, kind: int, moving: bool, z_left: float, z_right: float, variance: float
    ) -> OdometryEstimate:
        """Predict to `t_ns` and update with two wheel readings of `kind` (each of `variance`) and the gyro."""
        assert self._t_ns is not None
        dt = self._dt(t_ns, self._t_ns)
        r_left = r_right = variance
        self._still_intervals = 0 if moving else self._still_intervals + 1
        if self._still_intervals >= 2:  # no tick for two intervals: the robot stands still (zero-velocity update)
            kind = _STILL
            z_left = z_right = 0.0
            r_left, r_right = self._still_var
        mark, anchor = self._gyro_mark(t_ns), self._gyro_anchor_rad
        if self._fuse_gyro and self._gyro_count and mark is not None and anchor is not None:
            fuse, z_gyro, r_gyro = True, (mark - anchor) / dt, self._gyro_var / self._gyro_count
        else:
            fuse, z_gyro, r_gyro = False, 0.0, 0.0
        if self._update_filterpy(dt, kind, moving, fuse, z_left, z_right, z_gyro, r_left, r_right, r_gyro):
            self._slip_detected(t_ns)
        self._gyro_anchor_rad = mark
        self._gyro_count = 0
        self._t_ns = t_ns
        self._estimate = self._make_estimate(t_ns)
        return self._estimate

    def _step_native(  # noqa: PLR0917 - the hot path takes plain numbers positionally
        self, t_ns: int, kind: int, moving: bool, z_left: float, z_right: float, variance: float
    ) -> OdometryEstimate:
        """`_step_filterpy` in the compiled kernel, which does the standstill and gyro logic too."""
        assert self._t_ns is not None
        dt = self._dt(t_ns, self._t_ns)
        mark, anchor = self._gyro_mark(t_ns), self._gyro_anchor_rad
        if mark is not None and anchor is not None:
            turned_rad, count = mark - anchor, self._gyro_count
        else:
            turned_rad, count = 0.0, 0
        row = self._row
        if row == _COVARIANCE_ROWS:
            self._new_covariance_block()
            row = 0
        self._row = row + 1
        self._ws_c[self._in : self._in_end] = (
            dt,
            kind,
            moving,
            z_left,
            z_right,
            variance,
            turned_rad,
            count,
            row,
        )
        status = self._kernel_step()
        if status:
            if status < 0:
                raise EstimationError(NOT_POSITIVE_DEFINITE)
            self._slip_detected(t_ns)
        self._gyro_anchor_rad = mark
        self._gyro_count = 0
        self._t_ns = t_ns
        x, y, yaw, v, rate, bias = self._out.tolist()  # the kernel wrapped the yaw
        estimate: OdometryEstimate = _new_estimate(
            OdometryEstimate, (t_ns, x, y, yaw, v, rate, bias, self._poses[row], self._twists[row])
        )
        self._estimate = estimate
        return estimate

    def _slip_detected(self, t_ns: int) -> None:
        self.slip_detections += 1
        _log.debug("t=%d ns: wheels and gyro disagree beyond their noise; wheel slip assumed", t_ns)

    def _update_filterpy(  # noqa: PLR0917 - one private call site
        self,
        dt: float,
        kind: int,
        moving: bool,
        fuse: bool,
        z_left: float,
        z_right: float,
        z_gyro: float,
        r_left: float,
        r_right: float,
        r_gyro: float,
    ) -> bool:
        """Predict over `dt` and update through `SolvedEkf`; return True if the slip gate fired."""
        ekf = self.ekf
        ekf.dt = dt
        ekf.predict()
        z, r = self._z, self._r3
        z[0], z[1], z[2] = z_left, z_right, z_gyro
        r[0, 1] = r[1, 0] = 0.0
        r[0, 0], r[1, 1], r[2, 2] = r_left, r_right, r_gyro
        if not fuse:
            ekf.update_linear(z[:2], self._wheel_rows[kind], r[:2, :2], innovation=self._innovation(kind, 2))
            return False
        if moving:  # the gyro owns the yaw: turning wheels may slip
            self._release_differential_travel(kind)
        h, y = self._h[kind], self._innovation(kind, 3)
        if ekf.update_linear(z, h, r, innovation=y, gate=self._gate):
            return False
        if not moving:
            self._release_differential_travel(kind)
        ekf.update_linear(z, h, r, innovation=y)
        return True

    def _innovation(self, kind: int, rows: int) -> FloatArray:
        """`z - H x` for the first `rows` rows of the measurement matrix of `kind`."""
        x = self.ekf.x.tolist()
        z = self._z
        return np.array([z[i] - sum(c * x[j] for j, c in terms) for i, terms in enumerate(self._sparse[kind][:rows])])

    def _release_differential_travel(self, kind: int) -> None:
        """Make the wheels' differential travel over this interval unknown; their common travel stays.

        With wheel angles the angle states take the freedom (so they re-anchor to the readings); with
        wheel speeds the speed measurement does; at standstill the zero yaw rate is dropped.
        """
        if kind == _ANGLES:
            p = self.ekf.P
            p[6, 6] += _SLIP_RELEASE_RAD2
            p[7, 7] += _SLIP_RELEASE_RAD2
            p[6, 7] -= _SLIP_RELEASE_RAD2
            p[7, 6] -= _SLIP_RELEASE_RAD2
        elif kind == _SPEEDS:
            self._r3[:2, :2] += _RELEASE
        else:
            self._r3[1, 1] += _SLIP_RELEASE_RAD2

    def _make_estimate(self, t_ns: int) -> OdometryEstimate:
        padded = self._padded
        padded[: N_STATE * N_STATE] = self.ekf.P.ravel(order="K")  # no copy; P is symmetric, so order does not matter
        both = padded[_BOTH_GATHER]  # a fresh array: the estimate owns its covariances
        x, y, yaw, v, rate, bias, _, _ = self.ekf.x.tolist()
        yaw = (yaw + math.pi) % (2.0 * math.pi) - math.pi
        return _new_estimate(OdometryEstimate, (t_ns, x, y, yaw, v, rate, bias, both[:36], both[36:]))


def _not_finite(t_ns: int, left: float, right: float) -> str:
    return f"wheel reading at t={t_ns} ns is not a finite number: left {left}, right {right}"


def _rows(n: int, rows: list[dict[int, float]]) -> FloatArray:
    out = np.zeros((len(rows), n), order="F")
    for i, row in enumerate(rows):
        for j, value in row.items():
            out[i, j] = value
    return out
