"""Layer 2: state estimation. The odometry EKF fusing wheel encoders and the gyro, and its offline replay.

The only package that imports filterpy.
"""

from twin.estimation.config import EstimationSection
from twin.estimation.ekf import OdometryEstimate, OdometryFilter

__all__ = ["EstimationSection", "OdometryEstimate", "OdometryFilter"]
