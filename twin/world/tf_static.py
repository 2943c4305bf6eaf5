"""The robot's fixed transforms as robot_state_publisher publishes them on /tf_static for a TurtleBot3.

Gazebo's TurtleBot3 SDFs and the URDFs robot_state_publisher reads differ in two ways that show in
/tf_static: the SDF's ball-jointed casters are `fixed` joints in the URDF (so they are static), and
the URDF adds an optical frame under each camera frame (`camera_rgb_frame` ->
`camera_rgb_optical_frame`), rotated into the optical convention (z forward, x right, y down) with
the URDF's own rounded angles, rpy (-1.57, 0, -1.57).
"""

from __future__ import annotations

from twin.core.geometry import Mat4, Pose, matrix_from_pose
from twin.world.robot_model import RobotModelSpec
from twin.world.types import JointType

__all__ = ["OPTICAL_RPY", "static_frames"]

OPTICAL_RPY = (-1.57, 0.0, -1.57)  # turtlebot3_description's camera_rgb_optical_joint
_STATIC = (JointType.FIXED, JointType.BALL)  # ball casters: fixed joints in the TB3 URDFs
_CAMERA_FRAMES = ("_rgb_frame", "_depth_frame")


def static_frames(robot: RobotModelSpec) -> list[tuple[str, str, Mat4]]:
    """(parent, child, T_parent) of every transform the robot publishes once, on /tf_static."""
    out = [(f.parent, f.name, f.T_parent) for f in robot.frames if f.joint_type in _STATIC]
    names = {f.name for f in robot.frames}
    rotation = matrix_from_pose(Pose(roll_rad=OPTICAL_RPY[0], pitch_rad=OPTICAL_RPY[1], yaw_rad=OPTICAL_RPY[2]))
    for frame in robot.frames:
        if frame.joint_type is JointType.FIXED and frame.name.endswith(_CAMERA_FRAMES):
            optical = frame.name.removesuffix("_frame") + "_optical_frame"
            if optical not in names:
                out.append((frame.name, optical, rotation))
    return out
