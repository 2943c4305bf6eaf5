"""nav2_smoother: the SimpleSmoother smoother_server runs for SmoothPath (`simple_smoother`)."""
