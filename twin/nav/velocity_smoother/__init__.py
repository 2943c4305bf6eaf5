"""nav2_velocity_smoother: `VelocitySmoother` (open and closed loop) and `VelocitySmootherNode`."""
