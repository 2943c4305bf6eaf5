"""twin: a headless digital twin of a differential-drive robot (TurtleBot3 by default)."""

__version__ = "0.1.0"
