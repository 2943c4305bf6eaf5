"""Layer 3: offline bag analysis. Metrics, reports with plots, bag comparison, export.

Reads bags through `twin.bag` (any rosbag2: MCAP or sqlite3, metadata 4 to 9, any distro) in
one streaming pass; never imports `twin.sim`. Plots use matplotlib's Agg backend.
"""

from twin.analysis.metrics import GoalResult, RunMetrics, run_metrics

__all__ = ["GoalResult", "RunMetrics", "run_metrics"]
