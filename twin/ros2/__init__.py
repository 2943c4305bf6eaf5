"""The ROS 2 bridge: a run as a participant of a real ROS 2 domain over DDS (docs/ros2.md).

Layer 4, beside `twin.live`: it imports neither `twin.sim` nor anything above it, and nothing below
imports it (the executor takes it as a sink; the CLI reads the scenario's `ros2:` section). Cyclone
DDS is imported only when a bridge is made, so a run without `--ros2` never loads it.
"""

from twin.ros2.bridge import INBOUND_RATE_HZ, Ros2Bridge, cyclone_config
from twin.ros2.dds_types import dds_topic_name, dds_type_name

__all__ = ["INBOUND_RATE_HZ", "Ros2Bridge", "cyclone_config", "dds_topic_name", "dds_type_name"]
