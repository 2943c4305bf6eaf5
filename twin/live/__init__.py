"""Layer 3: the live view. A Foxglove WebSocket server for a running simulation or a bag, paced to real time.

`LiveServer` publishes ROS 2 topics (CDR bytes, `ros2msg` schemas) as foxglove_bridge does;
`LiveSink` is one more of a run's sinks, after the recorder, publishing to it; `Pacer` holds sim time to the wall
clock at any speed; `play_bag` serves a recorded bag. The only package that imports foxglove-sdk.
"""

from twin.live.pacing import Pacer, check_speed
from twin.live.play import PlayReport, play_bag
from twin.live.server import DEFAULT_HOST, DEFAULT_PORT, LiveServer
from twin.live.sink import LiveSink, is_latched

__all__ = [
    "DEFAULT_HOST",
    "DEFAULT_PORT",
    "LiveServer",
    "LiveSink",
    "Pacer",
    "PlayReport",
    "check_speed",
    "is_latched",
    "play_bag",
]
