"""Drive wheels read from a bag's URDF: TurtleBot3's pair, a skid-steer robot's axles."""

from __future__ import annotations

import pytest

from twin.world.urdf_wheels import wheels_from_urdf


def _wheel(name: str, x: float, y: float) -> str:
    return (
        f'<link name="{name}_link"><collision><geometry><cylinder radius="0.06" length="0.04"/></geometry>'
        f'</collision></link><joint name="{name}" type="continuous"><parent link="base_link"/>'
        f'<child link="{name}_link"/><origin xyz="{x} {y} 0.03"/><axis xyz="0 1 0"/></joint>'
    )


def test_a_four_wheel_skid_steer_robot_gives_an_axle_pair_not_a_diagonal() -> None:
    # Joints listed so that the first left and first right wheels are on different axles.
    urdf = (
        '<robot name="abitobot"><link name="base_link"/>'
        + _wheel("front_left_wheel_joint", 0.15, 0.2)
        + _wheel("rear_right_wheel_joint", -0.15, -0.2)
        + _wheel("rear_left_wheel_joint", -0.15, 0.2)
        + _wheel("front_right_wheel_joint", 0.15, -0.2)
        + "</robot>"
    )
    wheels = wheels_from_urdf(urdf)
    assert wheels is not None
    assert (wheels.left_joint, wheels.right_joint) == ("front_left_wheel_joint", "front_right_wheel_joint")
    assert wheels.wheel_separation_m == pytest.approx(0.4)  # the track, not the 0.5 m diagonal
    assert wheels.wheel_radius_m == pytest.approx(0.06)
    assert wheels.skid_steer
    assert set(wheels.left_joints) == {"front_left_wheel_joint", "rear_left_wheel_joint"}
    assert set(wheels.right_joints) == {"front_right_wheel_joint", "rear_right_wheel_joint"}


def test_a_differential_drive_is_not_skid_steer() -> None:
    urdf = (
        '<robot name="tb3"><link name="base_link"/>' + _wheel("wl", 0.0, 0.144) + _wheel("wr", 0.0, -0.144) + "</robot>"
    )
    wheels = wheels_from_urdf(urdf)
    assert wheels is not None and not wheels.skid_steer
    assert wheels.wheel_separation_m == pytest.approx(0.288)
