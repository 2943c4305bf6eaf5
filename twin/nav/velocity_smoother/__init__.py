"""nav2_velocity_smoother: `VelocitySmoother` (open loop) and `VelocitySmootherNode`."""
