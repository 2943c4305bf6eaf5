"""The robot as the simulation needs it, read from its SDF model: frames, drive, sensors, inertia.

Frames follow the URDF convention that robot_state_publisher and TF users expect: a link's frame is
the frame of the joint that attaches it to its parent (for SDF that is the child link's pose
composed with the joint's `<pose>`), the root link's frame is its own pose. Every pose here is
relative to the root frame (`base_footprint` for a TurtleBot3), and `base_height_m` says how high
that frame sits above the floor when the robot rests on its lowest collision shapes.

Scenario values override what the SDF says: build the spec, then `dataclasses.replace` the parts
(`replace(spec, lidar=replace(spec.lidar, rate_hz=10.0))`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Container, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from twin.core.errors import WorldError
from twin.core.geometry import Mat4, Pose, pose_from_matrix
from twin.world._xml import XmlNode
from twin.world.meshes import MeshCache, geometry_arrays
from twin.world.sdf import load_model
from twin.world.types import (
    Box,
    Capsule,
    Collision,
    Cylinder,
    Ellipsoid,
    Joint,
    JointType,
    Link,
    Model,
    Plugin,
    Sensor,
    Sphere,
    frozen_matrix,
    inverse,
)

__all__ = [
    "CameraSpec",
    "DiffDriveSpec",
    "FrameSpec",
    "ImuSpec",
    "JointStateSpec",
    "LidarSpec",
    "LinkInertia",
    "NoiseSpec",
    "RobotModelSpec",
    "in_namespace",
    "load_robot",
    "robot_spec_from_model",
]

_LIDAR_TYPES = ("ray", "gpu_ray", "lidar", "gpu_lidar")
_CAMERA_TYPES = ("camera", "depth")
# Gazebo's image formats the twin draws, and the sensor_msgs/Image encoding of each.
_IMAGE_FORMATS = {"R8G8B8": "rgb8", "RGB_INT8": "rgb8", "L8": "mono8", "L_INT8": "mono8"}
_MAX_IMAGE_SIDE = 8192
# By `Plugin.kind` (any spelling Gazebo accepts: `libgz-sim8-diff-drive-system.so`, `ignition-gazebo-...`).
_DIFF_DRIVE_PLUGINS = ("gazebo_ros_diff_drive", "gz-sim-diff-drive-system", "DiffDrivePlugin")  # (the last:
# Gazebo Classic's own, on Gazebo transport: its joints, the wheels' geometry, and the twin's cmd_vel)
_SKID_STEER = "SkidSteerDrivePlugin"
_JOINT_STATE_PLUGINS = ("gazebo_ros_joint_state_publisher", "gz-sim-joint-state-publisher-system")


@dataclass(frozen=True, kw_only=True, slots=True)
class NoiseSpec:
    """An SDF `<noise>`: Gaussian noise with mean and standard deviation, plus an optional bias.

    Gazebo draws the bias once per sensor from N(bias_mean, bias_stddev) with a random sign.
    """

    type: str = "none"
    mean: float = 0.0
    stddev: float = 0.0
    bias_mean: float = 0.0
    bias_stddev: float = 0.0
    dynamic_bias_stddev: float = 0.0
    dynamic_bias_correlation_time_s: float = 0.0
    precision: float = 0.0

    @property
    def active(self) -> bool:
        """True when the noise adds anything."""
        return self.type != "none" and (
            self.stddev > 0 or self.mean != 0 or self.bias_mean != 0 or self.bias_stddev > 0
        )


def in_namespace(topic: str | None, default: str) -> str:
    """A sensor plugin's topic as the twin publishes it, relative to the robot's namespace (`default` when none).

    An absolute one (`/scan`) is kept in the namespace too, so a fleet robot's topics stay under `/robot1/`.
    """
    return (topic or default).strip("/") or default


@dataclass(frozen=True, kw_only=True, slots=True)
class LidarSpec:
    """A planar lidar as Gazebo's ray sensor and gazebo_ros_ray_sensor publish it.

    `mount` is the sensor's pose in the robot's base frame; rays start `range_min_m` from it.
    """

    name: str = "lidar"
    frame_id: str = "base_scan"
    topic: str | None = None
    sensor_type: str = "ray"
    rate_hz: float = 5.0
    samples: int = 360
    resolution: float = 1.0
    angle_min_rad: float = 0.0
    angle_max_rad: float = 2 * math.pi
    range_min_m: float = 0.12
    range_max_m: float = 3.5
    range_resolution_m: float = 0.0
    noise_mean_m: float = 0.0
    noise_std_m: float = 0.0
    mount: Pose = field(default_factory=Pose)

    @property
    def scan_topic(self) -> str:
        """The scans' topic in the robot's namespace: the plugin's (`scan` when it names none)."""
        return in_namespace(self.topic, "scan")

    @property
    def count(self) -> int:
        """Number of ranges per scan (Gazebo's range count: samples x resolution)."""
        return max(1, int(self.samples * self.resolution))

    @property
    def angle_increment_rad(self) -> float:
        """Angle between beams as published: (max - min) / (count - 1), as Gazebo's `angle_step`."""
        return (self.angle_max_rad - self.angle_min_rad) / (self.count - 1) if self.count > 1 else 0.0


@dataclass(frozen=True, kw_only=True, slots=True)
class ImuSpec:
    """An IMU: rate, frame, mount, and per-axis noise of angular velocity and linear acceleration."""

    name: str = "imu"
    frame_id: str = "imu_link"
    topic: str | None = None
    rate_hz: float = 200.0
    mount: Pose = field(default_factory=Pose)
    angular_velocity_noise: tuple[NoiseSpec, NoiseSpec, NoiseSpec] = (NoiseSpec(), NoiseSpec(), NoiseSpec())
    linear_acceleration_noise: tuple[NoiseSpec, NoiseSpec, NoiseSpec] = (NoiseSpec(), NoiseSpec(), NoiseSpec())


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class CameraSpec:
    """A camera as Gazebo Classic's camera (or depth) sensor and gazebo_ros_camera publish it.

    `T_base_sensor` is the sensor frame (x forward, y left, z up: where Gazebo's camera looks along
    +x) in the robot's base frame; images are published in `frame_id` (the plugin's `frame_name`,
    conventionally the optical frame). Topics are absolute, namespace and remappings applied.
    """

    name: str = "camera"
    sensor_type: str = "camera"
    rate_hz: float = 30.0
    width: int = 320
    height: int = 240
    encoding: str = "rgb8"
    hfov_rad: float = 1.047
    near_m: float = 0.1
    far_m: float = 100.0
    noise_mean: float = 0.0
    noise_std: float = 0.0
    frame_id: str = "camera_link"
    image_topic: str = "/camera/image_raw"
    info_topic: str = "/camera/camera_info"
    depth_topic: str = "/camera/depth/image_raw"
    points_topic: str = "/camera/points"
    T_base_sensor: Mat4 = field(default_factory=lambda: frozen_matrix(np.eye(4)))
    where: str = ""

    @property
    def depth(self) -> bool:
        """True for a depth camera (it publishes a depth image beside the colour one)."""
        return self.sensor_type == "depth"


@dataclass(frozen=True, kw_only=True, slots=True)
class DiffDriveSpec:
    """The differential drive: wheel joints, geometry and the plugin's limits and frames."""

    left_joint: str
    right_joint: str
    wheel_separation_m: float
    wheel_radius_m: float
    max_wheel_acceleration_mps2: float | None = None
    """gazebo_ros_diff_drive's limit on the wheels' rim speed change (0 or None: unlimited)."""
    max_linear_acceleration_mps2: float | None = None
    """gz-sim DiffDrive's limit on the body's linear acceleration (`max_linear_acceleration`, or its older
    `max_acceleration`); the FMU drive takes it as its rim acceleration limit when the plugin gives no
    `max_wheel_acceleration`."""
    linear_velocity_limits_mps: tuple[float, float] | None = None
    """gz-sim DiffDrive's commanded linear speed range (`min_`/`max_linear_velocity`; the older
    `min_`/`max_velocity` limit the turn rate too); a bound it does not give is none."""
    angular_velocity_limits_radps: tuple[float, float] | None = None
    """gz-sim DiffDrive's commanded turn rate range (`min_`/`max_angular_velocity`, else `min_`/`max_velocity`)."""
    more_wheels: tuple[tuple[str, int], ...] = ()
    """The plugin's further wheel joints (a repeated `<left_joint>`/`<right_joint>`: several pairs), each
    with its side (0 left, 1 right): they turn as the first pair's wheel of their side."""
    max_wheel_torque_nm: float | None = None
    update_rate_hz: float | None = None
    command_topic: str = "cmd_vel"
    odometry_topic: str = "odom"
    odometry_frame: str = "odom"
    base_frame: str = "base_footprint"
    publish_odom: bool = True
    publish_odom_tf: bool = True
    publish_wheel_tf: bool = False
    plugin: str | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class JointStateSpec:
    """Joint-state publishing as the SDF declares it."""

    joints: tuple[str, ...]
    rate_hz: float = 30.0
    topic: str = "joint_states"


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class FrameSpec:
    """One frame of the robot's tree: its parent and the transform at zero joint position.

    `axis` is the joint axis in this frame (continuous and revolute joints rotate about it).
    """

    name: str
    parent: str
    T_parent: Mat4
    joint: str
    joint_type: JointType
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class LinkInertia:
    """A link's mass, centre of mass (in the base frame) and inertia about it (in the link frame)."""

    link: str
    mass_kg: float
    T_base_com: Mat4
    inertia_kgm2: tuple[float, float, float, float, float, float]


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class RobotModelSpec:
    """Everything the simulation needs to know about the robot, read once from its SDF."""

    name: str
    base_frame: str
    base_height_m: float
    frames: tuple[FrameSpec, ...]
    drive: DiffDriveSpec | None
    lidar: LidarSpec | None
    imu: ImuSpec | None
    joint_states: JointStateSpec | None
    inertias: tuple[LinkInertia, ...]
    collisions: tuple[Collision, ...]
    """Collision shapes; each `T_world` is the pose in the base frame."""
    model: Model
    T_base_model: Mat4
    """Pose of the SDF model frame in the base frame (to place the model's links and visuals)."""
    source: Path | None = None
    warnings: tuple[str, ...] = ()
    cameras: tuple[CameraSpec, ...] = ()
    """Camera and depth sensors, in the SDF's order."""
    links: tuple[Link, ...] = ()
    """Every link of the model and its nested models, each `T_model` in the robot model's frame and
    named as the robot's frames name it (a nested model's `hokuyo::link`)."""

    @property
    def mass_kg(self) -> float:
        """Sum of the link masses."""
        return sum(i.mass_kg for i in self.inertias)

    def frame(self, name: str) -> FrameSpec:
        """Return a frame by name.

        Raises:
            KeyError: If the robot has no such frame.
        """
        for frame in self.frames:
            if frame.name == name:
                return frame
        raise KeyError(name)

    def T_base(self, name: str) -> Mat4:
        """Return the pose of a frame in the base frame (zero joint positions)."""
        if name == self.base_frame:
            return np.eye(4)
        frame = self.frame(name)
        return self.T_base(frame.parent) @ frame.T_parent


# --- reading sensors and plugins -----------------------------------------------------------------


def _noise(node: XmlNode | None) -> NoiseSpec:
    if node is None:
        return NoiseSpec()
    kind = node.get("type") or node.text_at("type") or "none"
    return NoiseSpec(
        type=kind.strip().lower(),
        mean=node.float_at("mean", 0.0),
        stddev=node.float_at("stddev", 0.0),
        bias_mean=node.float_at("bias_mean", 0.0),
        bias_stddev=node.float_at("bias_stddev", 0.0),
        dynamic_bias_stddev=node.float_at("dynamic_bias_stddev", 0.0),
        dynamic_bias_correlation_time_s=node.float_at("dynamic_bias_correlation_time", 0.0),
        precision=node.float_at("precision", 0.0),
    )


def _plugin_topic(element: XmlNode) -> str | None:
    for node in element.findall("plugin"):
        plugin = Plugin(name=node.get("name") or "", filename=node.get("filename") or "", element=node)
        remapped = _remapped(plugin)
        ros = node.find("ros")
        if ros is not None and plugin.kind.startswith("gazebo_ros_"):
            # A gazebo_ros sensor plugin publishes `~/out` of its node (named as the plugin), in
            # its `<ros><namespace>`: `~/out:=scan` in namespace `/dolly` is `/dolly/scan`.
            target = remapped or f"{plugin.name or 'out'}/out"
            namespace = (ros.text_at("namespace") or "").strip("/")
            if target.startswith("~/"):
                target = f"{plugin.name}/{target[2:]}"
            return target if target.startswith("/") or not namespace else f"{namespace}/{target}"
        if remapped:
            return remapped
        for tag in ("topicName", "topic_name"):
            if node.text_at(tag):
                return node.text_at(tag)
    return element.text_at("topic")


def _frame_id(element: XmlNode, link_name: str) -> str:
    for plugin in element.findall("plugin"):
        for tag in ("frame_name", "frameName"):
            if plugin.text_at(tag):
                return plugin.text_at(tag) or link_name
    for tag in ("gz_frame_id", "ignition_frame_id", "frame_id"):
        if element.text_at(tag):
            return element.text_at(tag) or link_name
    return link_name


def _lidar(sensor: Sensor, link: Link, T_base_model: Mat4) -> LidarSpec:
    element = sensor.element
    assert element is not None
    body = element.find("ray")
    if body is None:
        body = element.find("lidar")
    if body is None:
        msg = f"{sensor.where}: sensor {sensor.name!r} of type {sensor.type!r} has no <ray> or <lidar> element"
        raise WorldError(msg)
    noise = _noise(body.find("noise"))
    mount = T_base_model @ np.asarray(link.T_model) @ np.asarray(sensor.T_link)
    return LidarSpec(
        name=sensor.name,
        frame_id=_frame_id(element, link.name),
        topic=_plugin_topic(element),
        sensor_type=sensor.type,
        rate_hz=sensor.update_rate_hz,
        samples=int(body.float_at("scan/horizontal/samples", 640)),
        resolution=body.float_at("scan/horizontal/resolution", 1.0),
        angle_min_rad=body.float_at("scan/horizontal/min_angle", 0.0),
        angle_max_rad=body.float_at("scan/horizontal/max_angle", 0.0),
        range_min_m=body.float_at("range/min", 0.0),
        range_max_m=body.float_at("range/max", 0.0),
        range_resolution_m=body.float_at("range/resolution", 0.0),
        noise_mean_m=noise.mean if noise.type != "none" else 0.0,
        noise_std_m=noise.stddev if noise.type != "none" else 0.0,
        mount=pose_from_matrix(mount),
    )


def _imu(sensor: Sensor, link: Link, T_base_model: Mat4) -> ImuSpec:
    element = sensor.element
    assert element is not None
    imu = element.find("imu")
    gyro: list[NoiseSpec] = [NoiseSpec()] * 3
    accel: list[NoiseSpec] = [NoiseSpec()] * 3
    if imu is not None:
        for i, axis in enumerate("xyz"):
            gyro[i] = _noise(imu.path(f"angular_velocity/{axis}/noise"))
            accel[i] = _noise(imu.path(f"linear_acceleration/{axis}/noise"))
        old = imu.find("noise")  # SDF 1.4/1.5: one <noise> with <rate> and <accel> blocks
        if old is not None:
            kind = old.text_at("type") or "gaussian"
            for target, tag in ((gyro, "rate"), (accel, "accel")):
                block = old.find(tag)
                if block is not None:
                    spec = replace(_noise(block), type=kind)
                    target[:] = [spec] * 3
    mount = T_base_model @ np.asarray(link.T_model) @ np.asarray(sensor.T_link)
    return ImuSpec(
        name=sensor.name,
        frame_id=_frame_id(element, link.name),
        topic=_plugin_topic(element),
        rate_hz=sensor.update_rate_hz,
        mount=pose_from_matrix(mount),
        angular_velocity_noise=(gyro[0], gyro[1], gyro[2]),
        linear_acceleration_noise=(accel[0], accel[1], accel[2]),
    )


def _camera_topics(element: XmlNode, camera_name: str) -> dict[str, str]:
    """gazebo_ros_camera's topics: `<camera_name>/image_raw` etc. in the plugin's namespace, remapped."""
    suffixes = {"image": "image_raw", "info": "camera_info", "depth": "depth/image_raw", "points": "points"}
    plugin = next((p for p in element.findall("plugin") if "camera" in (p.get("filename") or "")), None)
    name = camera_name
    namespace = ""
    remaps: dict[str, str] = {}
    if plugin is not None:
        name = plugin.text_at("camera_name") or plugin.text_at("cameraName") or camera_name
        ros = plugin.find("ros")
        if ros is not None:
            namespace = (ros.text_at("namespace") or "").strip().strip("/")
            for remap in ros.findall("remapping"):
                if ":=" in remap.text:
                    source, target = (part.strip() for part in remap.text.split(":=", 1))
                    remaps[source.removeprefix("~/").lstrip("/")] = target
    topics = {}
    for key, suffix in suffixes.items():
        topic = f"{name}/{suffix}"
        topic = remaps.get(topic, remaps.get(suffix, topic))
        if not topic.startswith("/"):
            topic = f"/{namespace}/{topic}" if namespace else f"/{topic}"
        topics[key] = topic
    return topics


def _camera(sensor: Sensor, link: Link, T_base_model: Mat4) -> CameraSpec:
    """Read a `<sensor type="camera">` or `type="depth"` as Gazebo Classic does.

    Raises:
        WorldError: An image format the twin does not draw, a size that is not 1 to 8192 pixels, a
            horizontal_fov outside (0, pi), or clip planes with near not below far; one line naming
            the element.
    """
    element = sensor.element
    assert element is not None
    body = element.find("camera")
    if body is None:
        msg = f"{sensor.where}: sensor {sensor.name!r} of type {sensor.type!r} has no <camera> element; add one"
        raise WorldError(msg)
    where = body.where
    fmt = (body.text_at("image/format") or "R8G8B8").strip()
    if fmt not in _IMAGE_FORMATS:
        msg = f"{where}: camera {sensor.name!r}: image format {fmt!r} is not supported; use R8G8B8 (rgb8) or L8 (mono8)"
        raise WorldError(msg)
    width = body.float_at("image/width", 320)
    height = body.float_at("image/height", 240)
    for label, side in (("width", width), ("height", height)):
        if not (side == int(side) and 1 <= side <= _MAX_IMAGE_SIDE):
            msg = (
                f"{where}: camera {sensor.name!r}: image {label} {side:g} must be a whole number "
                f"from 1 to {_MAX_IMAGE_SIDE}"
            )
            raise WorldError(msg)
    hfov = body.float_at("horizontal_fov", 1.047)
    if not 0.0 < hfov < math.pi:
        msg = f"{where}: camera {sensor.name!r}: horizontal_fov {hfov:g} rad must be between 0 and pi"
        raise WorldError(msg)
    near = body.float_at("clip/near", 0.1)
    far = body.float_at("clip/far", 100.0)
    if not 0.0 < near < far:
        msg = f"{where}: camera {sensor.name!r}: clip near {near:g} m must be above 0 and below far {far:g} m"
        raise WorldError(msg)
    noise = _noise(body.find("noise"))
    if noise.type not in ("none", "gaussian"):
        msg = f"{where}: camera {sensor.name!r}: noise type {noise.type!r} is not supported; use gaussian or none"
        raise WorldError(msg)
    topics = _camera_topics(element, sensor.name)
    T = T_base_model @ np.asarray(link.T_model) @ np.asarray(sensor.T_link)
    return CameraSpec(
        name=sensor.name,
        sensor_type=sensor.type,
        rate_hz=sensor.update_rate_hz,
        width=int(width),
        height=int(height),
        encoding=_IMAGE_FORMATS[fmt],
        hfov_rad=hfov,
        near_m=near,
        far_m=far,
        noise_mean=noise.mean if noise.type == "gaussian" else 0.0,
        noise_std=noise.stddev if noise.type == "gaussian" else 0.0,
        frame_id=_frame_id(element, link.name),
        image_topic=topics["image"],
        info_topic=topics["info"],
        depth_topic=topics["depth"],
        points_topic=topics["points"],
        T_base_sensor=frozen_matrix(T),
        where=sensor.where,
    )


def _float_param(plugin: Plugin, tag: str) -> float | None:
    text = plugin.param(tag)
    if text is None or text == "":
        return None
    try:
        return float(text)
    except ValueError:
        msg = f"{plugin.where}: <{tag}> of plugin {plugin.filename!r} must be a number, got {text!r}"
        raise WorldError(msg) from None


def _bool_param(plugin: Plugin, tag: str, default: bool) -> bool:
    text = plugin.param(tag)
    if text is None or text == "":
        return default
    return text.strip().lower() in ("1", "true")


# --- geometry helpers ----------------------------------------------------------------------------


def _lowest_z(collision: Collision, T: Mat4, cache: MeshCache) -> float:
    """Lowest point of a collision shape posed by T (exact for primitives)."""
    rz = T[2, :3]
    cz = float(T[2, 3])
    match collision.geometry:
        case Box(size_m=size):
            return cz - sum(abs(float(rz[i])) * size[i] / 2 for i in range(3))
        case Sphere(radius_m=r):
            return cz - r
        case Cylinder(radius_m=r, length_m=length):
            az = abs(float(rz[2]))
            return cz - az * length / 2 - r * math.sqrt(max(0.0, 1 - az * az))
        case Capsule(radius_m=r, length_m=length):
            return cz - abs(float(rz[2])) * length / 2 - r
        case Ellipsoid(radii_m=radii):
            return cz - math.sqrt(sum((float(rz[i]) * radii[i]) ** 2 for i in range(3)))
    mesh = geometry_arrays(collision.geometry, cache, collision.where)
    if mesh is None:
        return math.inf
    return float((mesh.vertices @ T[:3, :3].T + T[:3, 3])[:, 2].min())


# --- the spec ------------------------------------------------------------------------------------


def robot_spec_from_model(model: Model, *, base_frame: str = "base_footprint") -> RobotModelSpec:
    """Read a robot's frames, drive, lidar, IMU, inertias and collisions from its model.

    Args:
        model: The robot model (from `load_model`).
        base_frame: The root frame; if the model has no link of that name, its first link is the
            root.

    Raises:
        WorldError: If the model has no links, or a plugin or sensor parameter is malformed.
    """
    links, all_joints, plugins = _flattened(model)
    if not links:
        msg = f"{model.source}: model {model.name!r} has no links; a robot needs at least one"
        raise WorldError(msg)
    warnings: list[str] = []
    joints = {j.child: j for j in all_joints if j.parent != "world"}
    # Every frame of the tree in the model frame: links at their parent joint's frame (URDF style),
    # explicit <frame>s at their own pose. Edges: joint child -> parent, frame -> attached_to.
    T_model: dict[str, Mat4] = {}
    parent_of: dict[str, str] = {}
    edge_joint: dict[str, Joint] = {}
    for name, link in links.items():
        joint = joints.get(name)
        T_model[name] = np.asarray(joint.T_model if joint is not None else link.T_model)
        if joint is not None and joint.parent in links:
            parent_of[name] = joint.parent
            edge_joint[name] = joint
    for frame in model.frames:
        T_model.setdefault(frame.name, np.asarray(frame.T_model))
        if frame.attached_to in links or frame.attached_to in {f.name for f in model.frames}:
            parent_of[frame.name] = frame.attached_to
    root = base_frame if base_frame in T_model else model.links[0].name if model.links else next(iter(links))
    # Make `root` the top of the tree: reverse the edges on its path up (e.g. a base_footprint
    # frame attached to base_link becomes base_link's parent).
    path = [root]
    while path[-1] in parent_of and parent_of[path[-1]] not in path:
        path.append(parent_of[path[-1]])
    for child, parent in itertools.pairwise(path):
        del parent_of[child]
        parent_of[parent] = child
        edge_joint.pop(parent, None)
    T_base_model = inverse(T_model[root])
    frames: list[FrameSpec] = []
    for name, T_name in T_model.items():
        if name == root:
            continue
        parent = parent_of.get(name, root)
        if name not in parent_of and name in links:
            warnings.append(f"link {name!r} has no joint to a parent; it is fixed to {root!r}")
        joint = edge_joint.get(name)
        frames.append(
            FrameSpec(
                name=name,
                parent=parent,
                T_parent=frozen_matrix(inverse(T_model[parent]) @ T_name),
                joint=joint.name if joint is not None else "",
                joint_type=joint.type if joint is not None else JointType.FIXED,
                axis=joint.axis_xyz if joint is not None else (0.0, 0.0, 1.0),
            )
        )
    frames = _topological(frames, root)

    cache = MeshCache()
    collisions = []
    lowest = math.inf
    for link in links.values():
        for collision in link.collisions:
            T = T_base_model @ np.asarray(link.T_model) @ np.asarray(collision.T_link)
            collisions.append(replace(collision, T_world=frozen_matrix(T)))
            lowest = min(lowest, _lowest_z(collision, T, cache))
    base_height = -lowest if math.isfinite(lowest) else 0.0

    inertias = []
    for link in links.values():
        if link.inertial is None:
            continue
        T_com = T_base_model @ np.asarray(link.T_model) @ np.asarray(link.inertial.T_link)
        inertias.append(
            LinkInertia(
                link=link.name,
                mass_kg=link.inertial.mass_kg,
                T_base_com=frozen_matrix(T_com),
                inertia_kgm2=link.inertial.inertia_kgm2,
            )
        )

    lidars: list[LidarSpec] = []
    imu: ImuSpec | None = None
    cameras: list[CameraSpec] = []
    for link in links.values():
        for sensor in link.sensors:
            if sensor.type in _CAMERA_TYPES:
                cameras.append(_camera(sensor, link, T_base_model))
            elif sensor.type in _LIDAR_TYPES:
                lidars.append(_lidar(sensor, link, T_base_model))
            elif sensor.type == "imu" and imu is None:
                imu = _imu(sensor, link, T_base_model)
    lidar = _the_lidar(lidars, warnings)

    drive = _drive(model, plugins, all_joints, links=links, T_base_model=T_base_model, warnings=warnings, root=root)
    joint_states = None
    joint_names = {j.name for j in all_joints}
    for plugin in plugins:
        if plugin.kind in _JOINT_STATE_PLUGINS:
            names = tuple(_in_scope(plugin, name, joint_names) for name in plugin.params("joint_name"))
            rate = _float_param(plugin, "update_rate")
            topic = plugin.param("topic") or _remapped(plugin) or "joint_states"
            joint_states = JointStateSpec(joints=names, rate_hz=rate if rate else 30.0, topic=topic)
            break
    return RobotModelSpec(
        name=model.name,
        base_frame=root,
        base_height_m=base_height,
        frames=tuple(frames),
        drive=drive,
        lidar=lidar,
        imu=imu,
        joint_states=joint_states,
        inertias=tuple(inertias),
        collisions=tuple(collisions),
        model=model,
        T_base_model=frozen_matrix(T_base_model),
        source=model.source,
        warnings=tuple(warnings),
        cameras=tuple(cameras),
        links=tuple(links.values()),
    )


def _flattened(model: Model) -> tuple[dict[str, Link], list[Joint], list[Plugin]]:
    """The links, joints and plugins of a model and its nested models, in the model's frame.

    A nested model's (an `<include>`d lidar's) link is named by its scope below the model,
    `hokuyo::link`, as the model's own joints name it; its pose and its joints' are turned from
    the nested model's frame into the model's. A nested model's joints name their links and a
    nested plugin its joints in that scope too (`create::left_wheel`), each plugin remembering
    its scope (`Plugin.scope`).
    """
    prefix = f"{model.scoped_name}::"
    to_model = inverse(np.asarray(model.T_world))

    def scoped(owner: Model, name: str) -> str:
        if owner is model or name == "world":
            return name
        full = f"{owner.scoped_name}::{name}"
        return full.removeprefix(prefix)

    links: dict[str, Link] = {}
    joints: list[Joint] = list(model.joints)
    plugins: list[Plugin] = list(model.plugins)
    for owner in model.all_models():
        for link in owner.links:
            if owner is model:
                links[link.name] = link
            else:
                T = frozen_matrix(to_model @ np.asarray(link.T_world))
                links[scoped(owner, link.name)] = replace(link, name=scoped(owner, link.name), T_model=T)
        if owner is model:
            continue
        for joint in owner.joints:
            joints.append(
                replace(
                    joint,
                    name=scoped(owner, joint.name),
                    parent=scoped(owner, joint.parent),
                    child=scoped(owner, joint.child),
                    T_model=frozen_matrix(to_model @ np.asarray(joint.T_world)),
                )
            )
        plugins += [replace(p, scope=scoped(owner, "")) for p in owner.plugins]
    return links, joints, plugins


def _in_scope(plugin: Plugin, name: str, known: Container[str]) -> str:
    """A name a nested model's plugin gives (a joint), as the robot names it: in the plugin's scope when there."""
    scoped = f"{plugin.scope}{name}"
    return scoped if plugin.scope and scoped in known else name


def _the_lidar(lidars: Sequence[LidarSpec], warnings: list[str]) -> LidarSpec | None:
    """The lidar the twin simulates: the model's first ray sensor that scans (more than one beam).

    A one-beam ray sensor is a range finder (a Create's cliff sensors), not a scan; it is left out,
    as is every lidar after the first, each named in a warning.
    """
    scans = [lidar for lidar in lidars if lidar.samples > 1]
    beams = [lidar for lidar in lidars if lidar.samples <= 1]
    if beams:
        names = ", ".join(repr(b.name) for b in beams)
        warnings.append(f"one-beam ray sensor(s) {names} (range finders, not a scan) are not simulated")
    if len(scans) > 1:
        others = ", ".join(f"{o.name!r} ({o.scan_topic})" for o in scans[1:])
        warnings.append(
            f"the twin simulates one lidar per robot: {scans[0].name!r} on {scans[0].scan_topic}, not {others}"
        )
    return scans[0] if scans else None


def _topological(frames: list[FrameSpec], root: str) -> list[FrameSpec]:
    """Order frames so every parent comes before its children (TF publishers like that)."""
    done = {root}
    out: list[FrameSpec] = []
    pending = list(frames)
    while pending:
        ready = [f for f in pending if f.parent in done]
        if not ready:  # a cycle: leave the rest in file order
            out.extend(pending)
            break
        for frame in ready:
            out.append(frame)
            done.add(frame.name)
        pending = [f for f in pending if f.name not in done]
    return out


def _remapped(plugin: Plugin, source: str = "~/out") -> str | None:
    """The target of the plugin's `<ros><remapping>source:=target</remapping>`, or None."""
    ros = plugin.element.find("ros")
    if ros is None:
        return None
    # `<remapping>~/out:=scan</remapping>`, or ROS 2's older `<argument>~/out:=scan</argument>` /
    # `<argument>--ros-args -r ~/out:=scan</argument>`
    rules = [remap.text.strip() for remap in ros.findall("remapping")]
    rules += [token for argument in ros.findall("argument") for token in argument.text.split() if ":=" in token]
    for text in rules:
        if ":=" in text and text.split(":=", 1)[0].strip() == source:
            return text.split(":=", 1)[1].strip()
    return None


def _gazebo_ros_topic(plugin: Plugin, topic: str) -> str:
    """A gazebo_ros plugin's own topic (`cmd_vel`, `odom`) as its `<ros>` remaps and namespaces it.

    gazebo_ros_diff_drive in ROS 2 subscribes `cmd_vel` and publishes `odom` relative to its node,
    whose namespace is `<ros><namespace>`; `<remapping>cmd_vel:=...</remapping>` renames them. (Its
    ROS 1 `<command_topic>` and `<odometry_topic>` are ignored, as the Humble plugin ignores them.)
    """
    target = _remapped(plugin, topic) or _remapped(plugin, f"~/{topic}") or topic
    if target.startswith("/"):
        return target
    ros = plugin.element.find("ros")
    namespace = (ros.text_at("namespace") or "").strip("/") if ros is not None else ""
    return f"{namespace}/{target}" if namespace else target


def _wheel_radius(link: Link | None) -> float | None:
    if link is None:
        return None
    for collision in link.collisions:
        match collision.geometry:
            case Cylinder(radius_m=r) | Sphere(radius_m=r) | Capsule(radius_m=r):
                return r
    return None


def _drive(
    model: Model,
    plugins: Sequence[Plugin],
    all_joints: Sequence[Joint],
    *,
    links: dict[str, Link],
    T_base_model: Mat4,
    warnings: list[str],
    root: str,
) -> DiffDriveSpec | None:
    plugin = next((p for p in plugins if p.kind in _DIFF_DRIVE_PLUGINS), None)
    by_name = {j.name: j for j in all_joints}
    left_name = plugin.param("left_joint") if plugin is not None else None
    right_name = plugin.param("right_joint") if plugin is not None else None
    if plugin is not None:
        left_name = _in_scope(plugin, left_name, by_name) if left_name is not None else None
        right_name = _in_scope(plugin, right_name, by_name) if right_name is not None else None
    # Gazebo Classic's SkidSteerDrivePlugin (a Pioneer 3AT's): its front pair drives as a diff drive,
    # the rear pair turns with it; radius and separation from the wheels, as the plugin takes them
    skid = None if plugin is not None else next((p for p in plugins if p.kind == _SKID_STEER), None)
    skid_rear: tuple[tuple[str, int], ...] = ()
    if skid is not None:
        names = [skid.param(tag) for tag in ("left_front", "right_front", "left_rear", "right_rear")]
        if all(names) and all(_in_scope(skid, n, by_name) in by_name for n in names if n):
            left_name, right_name, rear_left, rear_right = (_in_scope(skid, n, by_name) for n in names if n)
            skid_rear = ((rear_left, 0), (rear_right, 1))
    if left_name is None or right_name is None:
        wheels = [j for j in all_joints if j.type in (JointType.REVOLUTE, JointType.CONTINUOUS) and "wheel" in j.name]
        left_name = left_name or next((j.name for j in wheels if "left" in j.name), None)
        right_name = right_name or next((j.name for j in wheels if "right" in j.name), None)
    if left_name is None or right_name is None:
        return None
    left, right = by_name.get(left_name), by_name.get(right_name)
    if left is None or right is None:
        where = plugin.where if plugin is not None else str(model.source)
        missing = left_name if left is None else right_name
        msg = f"{where}: the diff drive names joint {missing!r}, which model {model.name!r} does not have"
        raise WorldError(msg)

    radius: float | None = None
    separation: float | None = None
    if plugin is not None:
        diameter = _float_param(plugin, "wheel_diameter")
        radius = diameter / 2 if diameter is not None else _float_param(plugin, "wheel_radius")
        separation = _float_param(plugin, "wheel_separation")
    geom_radius = _wheel_radius(links.get(left.child))
    p_left = (T_base_model @ np.asarray(left.T_model))[:3, 3]
    p_right = (T_base_model @ np.asarray(right.T_model))[:3, 3]
    axis = (T_base_model @ np.asarray(left.T_model))[:3, :3] @ np.asarray(left.axis_xyz)
    geom_separation = abs(float(np.dot(p_left - p_right, axis)))
    if radius is None:
        radius = geom_radius
    elif geom_radius is not None and abs(geom_radius - radius) > 0.02 * radius:
        warnings.append(
            f"diff drive wheel radius {radius} m differs from the wheel collision radius {geom_radius} m: the "
            f"twin drives with {radius} m (Gazebo's physics rolls the collision's, {geom_radius / radius:.2f}x as far)"
        )
    if separation is None:
        separation = geom_separation
    elif abs(geom_separation - separation) > 0.02 * separation:
        warnings.append(
            f"diff drive wheel separation {separation} m differs from the joints' {geom_separation:.4f} m: the twin "
            f"turns with {separation} m (Gazebo's physics turns on the joints', {separation / geom_separation:.2f}x "
            "the commanded rate)"
        )
    if radius is None or radius <= 0 or separation <= 0:
        msg = f"{model.source}: cannot tell the wheel radius and separation of model {model.name!r}"
        raise WorldError(msg)
    if plugin is None:
        return DiffDriveSpec(
            left_joint=left.name,
            right_joint=right.name,
            wheel_separation_m=separation,
            wheel_radius_m=radius,
            base_frame=root,
            more_wheels=skid_rear,
            plugin=skid.filename if skid_rear and skid is not None else None,
        )
    if plugin.kind == "gazebo_ros_diff_drive":
        command_topic, odometry_topic = _gazebo_ros_topic(plugin, "cmd_vel"), _gazebo_ros_topic(plugin, "odom")
        legacies = (("command_topic", "cmd_vel", command_topic), ("odometry_topic", "odom", odometry_topic))
        for legacy, own, topic in legacies:
            named = (plugin.param(legacy) or own).strip()
            if named.strip("/") not in (own, topic.strip("/")):  # a rename the plugin will not make
                warnings.append(
                    f"{plugin.where}: <{legacy}>{named}</{legacy}> is ROS 1's; gazebo_ros_diff_drive in ROS 2 "
                    f"ignores it and uses {topic!r}: rename with <ros><remapping>{own}:={named}</remapping></ros>"
                )
    else:  # gz-sim's DiffDrive: its Gazebo topics, as a ros_gz bridge of the same names carries them
        command_topic = plugin.param("topic") or "cmd_vel"
        odometry_topic = plugin.param("odom_topic") or "odom"
    more = tuple(
        (_in_scope(plugin, name, by_name), side)
        for side, tag in enumerate(("left_joint", "right_joint"))
        for name in plugin.params(tag)[1:]
        if _in_scope(plugin, name, by_name) in by_name
    )
    return DiffDriveSpec(
        left_joint=left.name,
        right_joint=right.name,
        wheel_separation_m=separation,
        wheel_radius_m=radius,
        more_wheels=more,
        max_wheel_acceleration_mps2=_float_param(plugin, "max_wheel_acceleration"),
        max_linear_acceleration_mps2=_first_param(plugin, "max_linear_acceleration", "max_acceleration"),
        linear_velocity_limits_mps=_limits(plugin, "linear_velocity", "velocity"),
        angular_velocity_limits_radps=_limits(plugin, "angular_velocity", "velocity"),  # (the older names: both)
        max_wheel_torque_nm=_float_param(plugin, "max_wheel_torque"),
        update_rate_hz=_float_param(plugin, "update_rate"),
        command_topic=command_topic,
        odometry_topic=odometry_topic,
        odometry_frame=plugin.param("odometry_frame") or plugin.param("frame_id") or "odom",
        base_frame=plugin.param("robot_base_frame") or plugin.param("child_frame_id") or root,
        publish_odom=_bool_param(plugin, "publish_odom", True),
        publish_odom_tf=_bool_param(plugin, "publish_odom_tf", True),
        publish_wheel_tf=_bool_param(plugin, "publish_wheel_tf", False),
        plugin=plugin.filename,
    )


def _first_param(plugin: Plugin, *tags: str) -> float | None:
    """The first of the plugin's numeric parameters it gives (None: none of them)."""
    for tag in tags:
        value = _float_param(plugin, tag)
        if value is not None:
            return value
    return None


def _limits(plugin: Plugin, *names: str) -> tuple[float, float] | None:
    """gz-sim DiffDrive's `min_NAME`/`max_NAME` range (None: neither given).

    As gz-math's SpeedLimiter: a bound not given stays unbounded (a `max_` alone leaves reversing free).
    """
    high = _first_param(plugin, *(f"max_{n}" for n in names))
    low = _first_param(plugin, *(f"min_{n}" for n in names))
    if high is None and low is None:
        return None
    return (low if low is not None else -math.inf, high if high is not None else math.inf)


def load_robot(
    name_or_path: Path | str, *, model_path: Sequence[Path | str] = (), base_frame: str = "base_footprint"
) -> RobotModelSpec:
    """Load a robot model by name or path and read its spec (see `robot_spec_from_model`).

    Raises:
        WorldError: If the model cannot be found, loaded or read.
    """
    return robot_spec_from_model(load_model(name_or_path, model_path=model_path), base_frame=base_frame)
