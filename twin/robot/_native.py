"""The IMU's per-sample path in C: the chassis read, the sample and its `sensor_msgs/Imu` bytes in one call.

At 200 Hz the IMU is the most frequent event of a run. `ImuNode`'s Python path reads the chassis,
differentiates the heading, draws the sample (`ImuModel.sample`) and encodes it (`ImuEncoder`);
`twin_imu_sample` does the same arithmetic, in the same order, compiled without FMA contraction,
so its readings are the Python path's to the bit (the tests compare them), and writes the stamp
and the ten values into a message whose constant parts `ImuEncoder` made. It reads the chassis
from the compiled drive loop's structure (eight doubles: x, y, yaw, v, yaw rate, ax, ay, yaw
acceleration), so it runs with the FMU drive's compiled loop; anything else takes the Python path.

`TwinImu` (the `ImuState` structure below) holds the pointers, the noise block's rows (6 doubles
each: gyro x, y, z, accelerometer x, y, z errors) and the next row, the message's value offsets,
the last sample's time and heading, the model's constants (IMU axes in chassis axes as a 3x3
row-major rotation, the mount's x and y, minus gravity in IMU axes, the mount quaternion) and the
reading. `twin_imu_sample(state, t_ns)` returns 0, or 1 when the noise block is used up (nothing
done: refill it and call again).
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library, native_disabled

__all__ = ["ImuState", "load_imu_kernel"]

_SOURCE = r"""
#include <math.h>
#include <stdint.h>
#include <string.h>

typedef struct {
    const double *chassis;
    const double *noise;
    unsigned char *message;
    int64_t rows, next, stamp_at, orientation_at, angular_velocity_at, linear_acceleration_at, last_t_ns;
    double last_yaw;
    double k[18];
    double out[10];
} TwinImu;

static const double TAU = 6.283185307179586;

int twin_imu_sample(TwinImu *s, int64_t t_ns) {
    if (s->next >= s->rows) return 1;
    const double *c = s->chassis, *k = s->k;
    const double yaw = c[2], ax = c[5], ay = c[6], alpha = c[7];
    const int64_t dt_ns = t_ns - s->last_t_ns;
    const double w = dt_ns > 0 ? remainder(yaw - s->last_yaw, TAU) * 1e9 / (double)dt_ns : c[4];
    s->last_t_ns = t_ns;
    s->last_yaw = yaw;
    const double *n = s->noise + 6 * s->next++;
    const double w2 = w * w;
    const double fx = ax - alpha * k[10] - w2 * k[9];
    const double fy = ay + alpha * k[9] - w2 * k[10];
    const double sn = sin(0.5 * yaw), cs = cos(0.5 * yaw);
    double *o = s->out;
    o[0] = cs * k[14] - sn * k[15];
    o[1] = cs * k[15] + sn * k[14];
    o[2] = cs * k[16] + sn * k[17];
    o[3] = cs * k[17] - sn * k[16];
    o[4] = k[6] * w + n[0];
    o[5] = k[7] * w + n[1];
    o[6] = k[8] * w + n[2];
    o[7] = k[0] * fx + k[3] * fy + k[11] + n[3];
    o[8] = k[1] * fx + k[4] * fy + k[12] + n[4];
    o[9] = k[2] * fx + k[5] * fy + k[13] + n[5];
    const int32_t sec = (int32_t)(t_ns / 1000000000);
    const uint32_t nanosec = (uint32_t)(t_ns % 1000000000);
    unsigned char *m = s->message;
    memcpy(m + s->stamp_at, &sec, 4);
    memcpy(m + s->stamp_at + 4, &nanosec, 4);
    memcpy(m + s->orientation_at, o, 32);
    memcpy(m + s->angular_velocity_at, o + 4, 24);
    memcpy(m + s->linear_acceleration_at, o + 7, 24);
    return 0;
}
"""


class ImuState(ctypes.Structure):
    """`TwinImu` in the C source (same fields, same order)."""

    _fields_ = (
        ("chassis", ctypes.c_void_p),
        ("noise", ctypes.c_void_p),
        ("message", ctypes.c_void_p),
        ("rows", ctypes.c_int64),
        ("next", ctypes.c_int64),
        ("stamp_at", ctypes.c_int64),
        ("orientation_at", ctypes.c_int64),
        ("angular_velocity_at", ctypes.c_int64),
        ("linear_acceleration_at", ctypes.c_int64),
        ("last_t_ns", ctypes.c_int64),
        ("last_yaw", ctypes.c_double),
        ("k", ctypes.c_double * 18),
        ("out", ctypes.c_double * 10),
    )


def load_imu_kernel() -> ctypes.CDLL | None:
    """Return the compiled IMU sample (built on first use); None without a C compiler or with `TWIN_NO_NATIVE`."""
    return None if native_disabled() else _load()


@functools.cache
def _load() -> ctypes.CDLL | None:
    # Without FMA contraction: every product and sum rounds as Python's floats do.
    flags = ("-O2", "-shared", "-fPIC", "-ffp-contract=off")
    lib = load_library(CLibrary(name="imu_sample", source=_SOURCE, flags=flags), keep_gil=True)  # a 1 µs call
    if lib is None:
        return None
    lib.twin_imu_sample.restype = ctypes.c_int
    lib.twin_imu_sample.argtypes = [ctypes.c_void_p, ctypes.c_int64]
    return lib
