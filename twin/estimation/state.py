"""The odometry filter's state vector, shared by `OdometryFilter` (ekf) and its reference `SolvedEkf` (solved).

State `s = [x, y, yaw, v, yaw_rate, gyro_bias, wheel_left, wheel_right]` in the `odom` frame; the
model and the measurements are described in `twin.estimation.ekf`.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from numpy.typing import NDArray

__all__ = ["NOT_POSITIVE_DEFINITE", "N_STATE", "STATE_NAMES", "STRICTLY_LOWER", "FloatArray"]

FloatArray = NDArray[np.float64]

#: The state's components, with their units.
STATE_NAMES: Final = (
    "x_m",
    "y_m",
    "yaw_rad",
    "v_mps",
    "yaw_rate_radps",
    "gyro_bias_radps",
    "wheel_left_rad",
    "wheel_right_rad",
)
N_STATE: Final = len(STATE_NAMES)

#: Mask of the covariance's strictly lower triangle (mirrored from the upper one after an update).
STRICTLY_LOWER: Final = np.tril(np.ones((N_STATE, N_STATE), dtype=bool), -1)

#: The error an update raises when its innovation covariance has no Cholesky factor.
NOT_POSITIVE_DEFINITE: Final = (
    "EKF innovation covariance is not positive definite; every measurement needs a positive variance"
)
