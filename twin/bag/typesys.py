"""Message types the twin records: Humble's standard definitions plus nav2_msgs and twin_msgs.

Every bag the twin writes embeds the full definition of each type it uses (MCAP schemas,
sqlite3 `message_definitions`), so a reader that has never heard of `twin_msgs` decodes them.
This module owns the definitions and turns them into what the storages need: the `ros2msg`
text (the type followed by each dependency after a `MSG:` separator) and the RIHS01 type hash
that Iron and later record.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError

from twin.core.config import suggest
from twin.core.errors import BagError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["EXTRA_DEFINITIONS", "MessageDefinition", "TypeRegistry"]

# nav2_msgs as Humble defines them (nav2_msgs 1.1.x); comments are ours.
_NAV2_PARTICLE = """\
# One weighted pose hypothesis of a particle filter.
geometry_msgs/Pose pose
float64 weight
"""
_NAV2_PARTICLE_CLOUD = """\
# The particles of AMCL's filter.
std_msgs/Header header
Particle[] particles
"""
_NAV2_BT_STATUS_CHANGE = """\
# A behaviour-tree node changing status (Humble layout, without Jazzy's uid field).
builtin_interfaces/Time timestamp   # when the node changed status
string node_name
string previous_status              # IDLE, RUNNING, SUCCESS or FAILURE
string current_status               # IDLE, RUNNING, SUCCESS or FAILURE
"""
_NAV2_BT_LOG = """\
# Status changes of a behaviour tree since the last message.
builtin_interfaces/Time timestamp   # when this log was published
BehaviorTreeStatusChange[] event_log
"""

# The twin's own types.
_TWIN_MOTOR_STATE = """\
# Electrical and mechanical state of the drive motors, one array entry per joint.
std_msgs/Header header
string[] name                 # joint names, e.g. wheel_left_joint, wheel_right_joint
float64[] voltage_v           # terminal voltage applied to the motor
float64[] current_a           # armature current
float64[] torque_nm           # torque delivered at the wheel
float64[] velocity_rad_s      # wheel angular velocity
float64[] velocity_command_rad_s  # wheel speed the cmd_vel asked for, after the velocity limits
bool[] saturated              # true while that command is beyond the motor's reach at its supply voltage
"""
_TWIN_CONTACT = """\
# The robot touching the world, as the twin's collision check reports it.
uint8 BEGIN = 1
uint8 END = 2
std_msgs/Header header              # stamp: sim time; frame_id: frame of position and normal
uint8 event                         # BEGIN when the contact starts, END when it ends
string robot_collision              # the robot's collision, e.g. base_footprint
string world_collision              # what it touched, e.g. model::link::collision
geometry_msgs/Point position        # contact point
geometry_msgs/Vector3 normal        # unit normal, pointing from the world into the robot
float64 depth_m                     # penetration depth
"""

#: Definitions (`.msg` text) of the types the Humble type store does not know.
EXTRA_DEFINITIONS: Mapping[str, str] = {
    "nav2_msgs/msg/Particle": _NAV2_PARTICLE,
    "nav2_msgs/msg/ParticleCloud": _NAV2_PARTICLE_CLOUD,
    "nav2_msgs/msg/BehaviorTreeStatusChange": _NAV2_BT_STATUS_CHANGE,
    "nav2_msgs/msg/BehaviorTreeLog": _NAV2_BT_LOG,
    "twin_msgs/msg/MotorState": _TWIN_MOTOR_STATE,
    "twin_msgs/msg/Contact": _TWIN_CONTACT,
}


@dataclass(frozen=True, kw_only=True, slots=True)
class MessageDefinition:
    """What a bag stores about a message type."""

    msgtype: str  #: e.g. `sensor_msgs/msg/Imu`
    encoding: str  #: `ros2msg`
    text: str  #: the type's fields, then each dependency after a separator line and `MSG: pkg/Type`
    type_hash: str  #: `RIHS01_<sha256>`, as Iron and later compute it


class TypeRegistry:
    """Humble's standard types plus nav2_msgs and twin_msgs, with definitions and hashes on demand.

    Each registry owns its own rosbags type store, so registering a type in one never changes
    another.
    """

    def __init__(self, extra: Mapping[str, str] = EXTRA_DEFINITIONS) -> None:
        self.store: Typestore = get_typestore(Stores.ROS2_HUMBLE)
        self._cache: dict[str, MessageDefinition] = {}
        for msgtype, text in extra.items():
            self.register(msgtype, text)

    def register(self, msgtype: str, text: str) -> None:
        """Add a type from its `.msg` text (or from a full `ros2msg` text with its dependencies).

        Raises:
            BagError: If the text does not parse.
        """
        try:
            self.store.register(get_types_from_msg(text, msgtype))
        except (TypesysError, ValueError) as err:
            msg = f"message definition of {msgtype} does not parse: {err}"
            raise BagError(msg) from None
        self._cache.pop(msgtype, None)

    def knows(self, msgtype: str) -> bool:
        """Whether the registry can describe (and so decode) `msgtype`."""
        return msgtype in self.store.fielddefs

    def definition(self, msgtype: str) -> MessageDefinition:
        """Return the embedded definition of `msgtype`.

        Raises:
            BagError: If the type is unknown, with the closest known name.
        """
        cached = self._cache.get(msgtype)
        if cached is not None:
            return cached
        if not self.knows(msgtype):
            hint = suggest(msgtype, sorted(self.store.fielddefs))
            hint = hint if hint.startswith("; did you mean") else ""
            msg = f"unknown message type {msgtype!r}{hint} (for a custom type, pass its .msg text as msgdef=)"
            raise BagError(msg)
        text, _ = self.store.generate_msgdef(msgtype, ros_version=2)
        definition = MessageDefinition(
            msgtype=msgtype, encoding="ros2msg", text=text, type_hash=self.store.hash_rihs01(msgtype)
        )
        self._cache[msgtype] = definition
        return definition
