"""Message definitions (`.msg` text) of the types the twin uses that ROS 2 Humble's standard set lacks.

nav2_msgs as Humble defines them (nav2_msgs 1.1.x) and the twin's own twin_msgs. The bag writer
embeds them in every bag; `twin.msgs` registers them so nodes can build and read these messages.
Text only: layer 0, so both the bag and the message packages take them from here.
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["EXTRA_DEFINITIONS"]

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
_TWIN_NAVIGATION_FEEDBACK = """\
# bt_navigator's NavigateToPose feedback: the fields of nav2_msgs/action/NavigateToPose_Feedback
# (Humble), as a message type every bag reader knows.
geometry_msgs/PoseStamped current_pose          # the robot's map pose
builtin_interfaces/Duration navigation_time     # since the goal was accepted
builtin_interfaces/Duration estimated_time_remaining  # distance remaining / current speed
int16 number_of_recoveries                      # behaviours (spin, backup, wait, ...) run for this goal
float32 distance_remaining                      # along the current path, m
"""
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
    "twin_msgs/msg/NavigationFeedback": _TWIN_NAVIGATION_FEEDBACK,
    "twin_msgs/msg/Contact": _TWIN_CONTACT,
}
