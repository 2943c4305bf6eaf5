"""The robot's camera as a scenario asks for it: `sensors.camera` over the robot SDF's camera sensor.

The camera is off unless `sensors.camera.enabled` is true (the thesis's mission has none, and its
bag stays as it was). Enabled, it needs a camera sensor in the robot's SDF (the Waffle's R200); the
scenario may change its size, rate, depth output and noise. In a fleet each robot whose section
enables it has its own, under its namespace, and sees the other robots where they stand.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from twin.core.errors import ConfigError
from twin.robot.camera import CameraFeed, CameraNode, camera_model
from twin.robot.chassis import ChassisState
from twin.sim.scenario import CameraSection
from twin.world import RobotModelSpec, World
from twin.world.obstacles import ObstacleField
from twin.world.render import Body, Renderer, body_of, lighting_of, prepare_noise, world_visuals
from twin.world.robot_model import CameraSpec

__all__ = ["Camera", "build_camera", "camera_spec", "namespaced", "robot_body"]


class Camera(NamedTuple):
    """The camera's node and its in-process feed (for `LookForObject`)."""

    node: CameraNode
    feed: CameraFeed


def camera_spec(robot: RobotModelSpec, section: CameraSection) -> CameraSpec:
    """The robot's first camera sensor with the scenario's overrides.

    Raises:
        ConfigError: If the robot's SDF has no camera sensor, or its update_rate is 0 and the
            scenario gives no rate.
    """
    if not robot.cameras:
        msg = (
            f'sensors.camera.enabled: robot {robot.name!r} has no <sensor type="camera"> in its SDF '
            f"({robot.source}); use a robot with one (turtlebot3_waffle) or set enabled: false"
        )
        raise ConfigError(msg)
    spec = robot.cameras[0]
    rate = section.rate_hz if section.rate_hz is not None else spec.rate_hz
    if not rate > 0.0:
        msg = f"sensors.camera.rate_hz: the SDF's camera {spec.name!r} has update_rate 0; give rate_hz"
        raise ConfigError(msg)
    return dataclasses.replace(
        spec,
        width=section.width if section.width is not None else spec.width,
        height=section.height if section.height is not None else spec.height,
        rate_hz=rate,
        noise_mean=spec.noise_mean if section.noise else 0.0,
        noise_std=spec.noise_std if section.noise else 0.0,
    )


def build_camera(
    section: CameraSection,
    robot: RobotModelSpec,
    world: World,
    chassis: Callable[[], ChassisState],
    *,
    obstacles: ObstacleField | None,
    rng: np.random.Generator,
    recorded: Callable[[str], bool],
    namespace: str = "",
    exclude_models: Sequence[str] | None = None,
    body: Body | None = None,
    others: Sequence[tuple[Body, Callable[[], ChassisState]]] = (),
) -> Camera | None:
    """The camera node of a scenario (or of one robot of a fleet), or None when `sensors.camera.enabled` is false.

    Construct it inside the robot's `launch_context` and `frame_prefix`, as its group's other nodes.

    Args:
        section: The robot's `sensors.camera`.
        robot: The robot (its camera sensor).
        world: The world whose visuals the camera sees (the robots' own models left out).
        chassis: The robot's planar pose now.
        obstacles: The scenario's obstacles and blocks.
        rng: The camera's noise stream.
        recorded: Whether the recorder records a topic or a user's node subscribes to it (then the
            camera renders every period).
        namespace: The robot's namespace: the sensor's topics go under it (`/robot1/camera/image_raw`),
            as gazebo_ros puts a robot spawned under a namespace.
        exclude_models: The world's models not drawn as world (default: the robot's own model).
        body: The robot's own visuals (default: read from its model).
        others: A fleet's other robots: their visuals and their planar poses now.

    Raises:
        ConfigError: See `camera_spec`.
        WorldError: If a visual's mesh cannot be read.
    """
    if not section.enabled:
        return None
    spec = namespaced(camera_spec(robot, section), namespace)
    lighting = lighting_of(world)
    excluded = (robot.name,) if exclude_models is None else tuple(exclude_models)
    renderer = Renderer(camera_model(spec), world_visuals(world, lighting, exclude_models=excluded), lighting)
    if section.noise:
        prepare_noise()  # now, not in the run's first frame
    feed = CameraFeed()
    depth = section.depth or spec.depth
    wanted = (
        recorded(spec.image_topic)
        or (depth and (recorded(spec.depth_topic) or recorded(spec.points_topic)))
        or (section.compressed and recorded(f"{spec.image_topic}/compressed"))
    )
    node = CameraNode(
        spec,
        renderer,
        lighting,
        chassis,
        feed,
        obstacles=obstacles,
        rng=rng,
        depth=depth,
        compressed=section.compressed,
        recorded=wanted,
        body=body if body is not None else robot_body(robot),
        others=others,
    )
    return Camera(node, feed)


def robot_body(robot: RobotModelSpec) -> Body:
    """The robot's visuals in its base frame, as a camera draws it.

    Raises:
        WorldError: If a visual's mesh cannot be read.
    """
    return body_of(robot.links, robot.T_base_model)


def namespaced(spec: CameraSpec, namespace: str) -> CameraSpec:
    """The sensor with its topics under a robot's namespace (`""`: as they are)."""
    ns = namespace.strip("/")
    if not ns:
        return spec
    return dataclasses.replace(
        spec,
        image_topic=f"/{ns}{spec.image_topic}",
        info_topic=f"/{ns}{spec.info_topic}",
        depth_topic=f"/{ns}{spec.depth_topic}",
        points_topic=f"/{ns}{spec.points_topic}",
    )
