"""`SolvedEkf`: filterpy's EKF with a solved gain and a Joseph-form update (see `twin.estimation.ekf`).

It is the reference the compiled kernel is tested against and the fallback without one. It lives
apart from `ekf` because importing filterpy imports scipy.stats (about a second of start-up), which
a run stepping through the kernel never needs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.linalg.blas import dgemm, dsymm, dsyr2k, dsyrk, dtrmm
from scipy.linalg.lapack import dposv

from twin.core.errors import EstimationError
from twin.estimation.state import N_STATE, NOT_POSITIVE_DEFINITE, STRICTLY_LOWER, FloatArray

__all__ = ["SolvedEkf"]


class SolvedEkf(ExtendedKalmanFilter):  # type: ignore[misc]
    """filterpy's EKF for the planar odometry state, with a solved gain and a Joseph-form update.

    `predict()` runs the model of the module docstring over `self.dt`, with the rate random walks
    `self.rate_variances` (per second) and the wheel-slip variance `self.slip_variance_per_rad` (per
    radian of wheel travel); `update()` keeps filterpy's signature. The state is a 1-D array of 8.

    The arithmetic goes straight to BLAS/LAPACK on Fortran-ordered arrays (numpy's `@` costs several
    times more per call on 8x8 matrices): `P F^T` and `H P` read only P's upper triangle (`dsymm`), the
    Joseph form is applied as symmetric rank-k updates of that triangle (`dsyr2k`, `dsyrk`), so it
    stays symmetric positive semi-definite by construction, and the lower triangle is mirrored from
    it at the end of each update. Unlike filterpy, `x_prior`, `P_prior`, `x_post` and `P_post` are
    not kept (four copies per step).

    Args:
        x0: Initial state.
        p0: Initial covariance.
        wheel_radius_m: Wheel radius `R`.
        wheel_separation_m: Wheel separation `B`.
    """

    def __init__(self, x0: FloatArray, p0: FloatArray, *, wheel_radius_m: float, wheel_separation_m: float) -> None:
        super().__init__(dim_x=N_STATE, dim_z=3)
        self.x = np.array(x0, dtype=float)
        self.P = np.array(p0, dtype=float, order="F")
        self._ft = np.asfortranarray(np.eye(N_STATE))  # F^T, Fortran-ordered, for BLAS
        self.F = self._ft.T  # filterpy's F: a view, so writing F[i, j] writes F^T[j, i]
        self.dt = 0.0
        self.rate_variances = (0.0, 0.0, 0.0)
        self.slip_variance_per_rad = 0.0
        self._inv_r = 1.0 / wheel_radius_m
        self._half_b = 0.5 * wheel_separation_m
        self._rhs = {m: np.empty((m, N_STATE + 1), order="F") for m in (1, 2, 3)}
        self._travel = (0.0, 0.0)

    def predict_x(self, u: Any = 0) -> None:
        """Advance the state by `self.dt` and set `self.F` to the model's Jacobian there."""
        dt = self.dt
        x, y, yaw, v, rate, _, left, right = self.x.tolist()
        heading = yaw + 0.5 * rate * dt
        c, s = math.cos(heading), math.sin(heading)
        step = v * dt
        wheel_v = dt * self._inv_r
        wheel_r = self._half_b * wheel_v
        half = 0.5 * dt * step
        f = self.F  # item writes: cheaper than one fancy-index scatter for eleven entries
        f[0, 2] = -step * s
        f[0, 3] = dt * c
        f[0, 4] = -half * s
        f[1, 2] = step * c
        f[1, 3] = dt * s
        f[1, 4] = half * c
        f[2, 4] = dt
        f[6, 3] = f[7, 3] = wheel_v
        f[6, 4] = -wheel_r
        f[7, 4] = wheel_r
        travel_left, travel_right = v * wheel_v - rate * wheel_r, v * wheel_v + rate * wheel_r
        self._travel = (travel_left, travel_right)
        state = self.x
        state[0] = x + step * c
        state[1] = y + step * s
        state[2] = yaw + rate * dt
        state[6] = left + travel_left
        state[7] = right + travel_right

    def predict(self, u: Any = 0) -> None:
        """Predict over `self.dt`: `P = F (P + Q_w dt) F^T + Q_slip`."""
        p, dt = self.P, self.dt
        qv, qr, qb = self.rate_variances
        p[3, 3] += qv * dt
        p[4, 4] += qr * dt
        p[5, 5] += qb * dt
        self.predict_x(u)
        ft = self._ft
        p = dgemm(1.0, ft, dsymm(1.0, p, ft), trans_a=1)  # F (P F^T)
        if self.slip_variance_per_rad:
            q = self.slip_variance_per_rad
            p[6, 6] += q * abs(self._travel[0])
            p[7, 7] += q * abs(self._travel[1])
        self.P = p

    def update(  # noqa: PLR0917 - filterpy's signature
        self,
        z: FloatArray,
        HJacobian: Callable[..., FloatArray],
        Hx: Callable[..., FloatArray],
        R: FloatArray | None = None,
        args: tuple[Any, ...] = (),
        hx_args: tuple[Any, ...] = (),
        residual: Callable[[FloatArray, FloatArray], FloatArray] = np.subtract,
    ) -> None:
        """Update with measurement `z` (filterpy's signature); the gain is solved, never inverted."""
        h = HJacobian(self.x, *args)
        innovation = residual(z, Hx(self.x, *hx_args))
        self.update_linear(np.asarray(z, dtype=float), h, self.R if R is None else R, innovation=innovation)

    def update_linear(
        self,
        z: FloatArray,
        h: FloatArray,
        r: FloatArray,
        *,
        innovation: FloatArray | None = None,
        gate: float | None = None,
    ) -> bool:
        """Update with a linear measurement `z = H s + noise(R)` in Joseph form.

        With `S = H P H^T + R`, one Cholesky solve `S [K^T | w] = [H P | y]` gives the gain and the
        normalised innovation squared `y^T w` for the gate; then
        `P <- (I - K H) P (I - K H)^T + K R K^T = P - (K H P + P H^T K^T) + (U K^T)^T (U K^T)`, with
        `S = U^T U`.

        Args:
            z: Measurement.
            h: Measurement matrix.
            r: Measurement covariance.
            innovation: `z - H x` if already computed.
            gate: Skip the update and return False when the normalised innovation squared exceeds it.

        Returns:
            True if the state was updated.

        Raises:
            EstimationError: If the innovation covariance is not positive definite (a measurement
                without variance).
        """
        hf = np.asfortranarray(h)  # no copy when it already is
        p = self.P
        hp = dsymm(1.0, p, hf, side=1)  # H P
        s = dgemm(1.0, hp, hf, 1.0, r, trans_b=1)  # H P H^T + R
        y = z - hf @ self.x if innovation is None else innovation
        rhs = self._rhs[len(y)]
        rhs[:, :N_STATE] = hp
        rhs[:, N_STATE] = y
        u, sol, info = dposv(s, rhs)
        if info:
            raise EstimationError(NOT_POSITIVE_DEFINITE)
        if gate is not None and y @ sol[:, N_STATE] > gate:
            return False
        kt = sol[:, :N_STATE]  # K^T
        self.x += y @ kt
        p = dsyr2k(-1.0, hp, kt, 1.0, p, trans=1, overwrite_c=1)  # P - K H P - P H^T K^T (upper)
        p = dsyrk(1.0, dtrmm(1.0, u, kt), 1.0, p, trans=1, overwrite_c=1)  # + K S K^T (upper)
        np.copyto(p, p.T, where=STRICTLY_LOWER)  # mirror the upper triangle
        self.P = p
        self.K, self.S, self.y = kt.T, s, y
        return True
