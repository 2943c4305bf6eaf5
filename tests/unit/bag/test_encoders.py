"""Every fast encoder produces exactly the bytes rosbags' serializer produces for the same message."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.bag import encoders as E
from twin.bag.typesys import TypeRegistry
from twin.core.errors import BagError

REG = TypeRegistry()
STORE = REG.store
T = STORE.types

stamps = st.integers(min_value=0, max_value=(2**31 - 1) * 10**9 + 999_999_999)
floats = st.floats(allow_nan=False, width=64)
frames = st.text(max_size=24)
names = st.lists(st.text(min_size=1, max_size=20), min_size=0, max_size=4)
cov = st.lists(floats, min_size=36, max_size=36)


def ser(msg: Any) -> bytes:
    return bytes(STORE.serialize_cdr(msg, msg.__msgtype__))


def time(t_ns: int) -> Any:
    return T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def header(t_ns: int, frame: str) -> Any:
    return T["std_msgs/msg/Header"](stamp=time(t_ns), frame_id=frame)


def vec(x: float, y: float, z: float) -> Any:
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def point(x: float, y: float, z: float) -> Any:
    return T["geometry_msgs/msg/Point"](x=x, y=y, z=z)


def quat(x: float, y: float, z: float, w: float) -> Any:
    return T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def pose7(p: Any) -> Any:
    return T["geometry_msgs/msg/Pose"](position=point(*p[:3]), orientation=quat(*p[3:]))


def planar(x: float, y: float, yaw: float) -> Any:
    return pose7((x, y, 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))


@given(stamps)
def test_clock(t: int) -> None:
    assert E.ClockEncoder().encode(t) == ser(T["rosgraph_msgs/msg/Clock"](clock=time(t)))


@given(floats, floats)
def test_twist_planar(vx: float, wz: float) -> None:
    expected = T["geometry_msgs/msg/Twist"](linear=vec(vx, 0.0, 0.0), angular=vec(0.0, 0.0, wz))
    assert E.TwistEncoder().encode(vx, wz) == ser(expected)


@given(st.lists(floats, min_size=6, max_size=6))
def test_twist_full(v: list[float]) -> None:
    expected = T["geometry_msgs/msg/Twist"](linear=vec(*v[:3]), angular=vec(*v[3:]))
    assert E.TwistEncoder().encode_full(v[:3], v[3:]) == ser(expected)


@given(stamps, frames, st.lists(floats, min_size=10, max_size=10), st.lists(floats, min_size=27, max_size=27))
def test_imu(t: int, frame: str, v: list[float], c: list[float]) -> None:
    covs = np.array(c).reshape(3, 9)
    enc = E.ImuEncoder(
        frame,
        orientation_covariance=covs[0],
        angular_velocity_covariance=covs[1],
        linear_acceleration_covariance=covs[2],
    )
    expected = T["sensor_msgs/msg/Imu"](
        header=header(t, frame),
        orientation=quat(*v[0:4]),
        orientation_covariance=covs[0],
        angular_velocity=vec(*v[4:7]),
        angular_velocity_covariance=covs[1],
        linear_acceleration=vec(*v[7:10]),
        linear_acceleration_covariance=covs[2],
    )
    assert enc.encode(t, *v) == ser(expected)


@given(stamps, frames, frames, st.lists(floats, min_size=5, max_size=5), cov, cov, st.booleans())
def test_odometry(
    t: int, frame: str, child: str, v: list[float], pc: list[float], tc: list[float], per_call: bool
) -> None:
    x, y, yaw, vx, wz = v
    if not math.isfinite(yaw):
        yaw = 0.0
    pose_cov, twist_cov = np.array(pc), np.array(tc)
    if per_call:
        data = E.OdometryEncoder(frame, child).encode(t, x, y, yaw, vx, wz, pose_cov, twist_cov)
    else:
        enc = E.OdometryEncoder(frame, child, pose_covariance=pose_cov, twist_covariance=twist_cov)
        data = enc.encode(t, x, y, yaw, vx, wz)
    expected = T["nav_msgs/msg/Odometry"](
        header=header(t, frame),
        child_frame_id=child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=planar(x, y, yaw), covariance=pose_cov),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=vec(vx, 0.0, 0.0), angular=vec(0.0, 0.0, wz)),
            covariance=twist_cov,
        ),
    )
    assert data == ser(expected)


@given(stamps, st.lists(st.tuples(frames, frames, st.lists(floats, min_size=7, max_size=7)), min_size=1, max_size=4))
def test_tf(t: int, transforms: list[tuple[str, str, list[float]]]) -> None:
    enc = E.TFEncoder([(p, c) for p, c, _ in transforms])
    expected = T["tf2_msgs/msg/TFMessage"](
        transforms=[
            T["geometry_msgs/msg/TransformStamped"](
                header=header(t, p),
                child_frame_id=c,
                transform=T["geometry_msgs/msg/Transform"](translation=vec(*v[:3]), rotation=quat(*v[3:])),
            )
            for p, c, v in transforms
        ]
    )
    assert enc.encode(t, [v for _, _, v in transforms]) == ser(expected)
    assert enc.encode(t, np.array([v for _, _, v in transforms])) == ser(expected)


def test_tf_planar_matches_full_pose() -> None:
    enc = E.TFEncoder([("odom", "base_footprint")])
    yaw = 0.7
    full = (1.0, 2.0, 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    assert enc.encode_planar(5, 1.0, 2.0, yaw) == enc.encode(5, [full])


@given(stamps, frames, names, st.data(), st.booleans())
def test_joint_state(t: int, frame: str, joints: list[str], data: st.DataObject, with_effort: bool) -> None:
    n = len(joints)
    arrays = [np.array(data.draw(st.lists(floats, min_size=n, max_size=n))) for _ in range(3)]
    enc = E.JointStateEncoder(joints, frame, with_effort=with_effort)
    effort = arrays[2] if with_effort else np.zeros(0)
    expected = T["sensor_msgs/msg/JointState"](
        header=header(t, frame), name=joints, position=arrays[0], velocity=arrays[1], effort=effort
    )
    got = enc.encode(t, arrays[0], arrays[1], arrays[2]) if with_effort else enc.encode(t, arrays[0], arrays[1])
    assert got == ser(expected)


@given(stamps, frames, names, st.data())
def test_motor_state(t: int, frame: str, joints: list[str], data: st.DataObject) -> None:
    n = len(joints)
    arrays = [np.array(data.draw(st.lists(floats, min_size=n, max_size=n))) for _ in range(5)]
    saturated = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)), dtype=bool)
    expected = T["twin_msgs/msg/MotorState"](
        header=header(t, frame),
        name=joints,
        voltage_v=arrays[0],
        current_a=arrays[1],
        torque_nm=arrays[2],
        velocity_rad_s=arrays[3],
        velocity_command_rad_s=arrays[4],
        saturated=saturated,
    )
    enc = E.MotorStateEncoder(joints, frame)
    assert enc.encode(t, *arrays[:4], velocity_command_rad_s=arrays[4], saturated=list(saturated)) == ser(expected)
    # Without the command, it reads NaN and not saturated.
    plain = T["twin_msgs/msg/MotorState"](
        header=header(t, frame),
        name=joints,
        voltage_v=arrays[0],
        current_a=arrays[1],
        torque_nm=arrays[2],
        velocity_rad_s=arrays[3],
        velocity_command_rad_s=np.full(n, np.nan),
        saturated=np.zeros(n, dtype=bool),
    )
    assert enc.encode(t, *arrays[:4]) == ser(plain)


@given(
    stamps,
    frames,
    st.lists(st.floats(width=32, allow_nan=False), min_size=7, max_size=7),
    st.integers(0, 400),
    st.booleans(),
    st.booleans(),
    st.randoms(use_true_random=False),
)
def test_scan(
    t: int, frame: str, geometry: list[float], n: int, with_intensities: bool, give_intensities: bool, rnd: Any
) -> None:
    rng = np.random.default_rng(rnd.randint(0, 2**32))
    ranges = rng.uniform(0.1, 3.5, n).astype(np.float32)
    ranges[rng.random(n) < 0.1] = np.inf
    intensities = rng.uniform(0, 100, n).astype(np.float32) if with_intensities else np.zeros(0, np.float32)
    enc = E.ScanEncoder(
        frame,
        angle_min_rad=geometry[0],
        angle_max_rad=geometry[1],
        angle_increment_rad=geometry[2],
        time_increment_s=geometry[3],
        scan_time_s=geometry[4],
        range_min_m=geometry[5],
        range_max_m=geometry[6],
        samples=n,
        with_intensities=with_intensities,
    )
    given_intensities = intensities if (with_intensities and give_intensities) else None
    expected_intensities = intensities if given_intensities is not None else np.zeros(n if with_intensities else 0)
    expected = T["sensor_msgs/msg/LaserScan"](
        header=header(t, frame),
        angle_min=geometry[0],
        angle_max=geometry[1],
        angle_increment=geometry[2],
        time_increment=geometry[3],
        scan_time=geometry[4],
        range_min=geometry[5],
        range_max=geometry[6],
        ranges=ranges,
        intensities=expected_intensities.astype(np.float32),
    )
    assert enc.encode(t, ranges, given_intensities) == ser(expected)
    # float64 ranges are converted, not rejected
    assert enc.encode(t, ranges.astype(np.float64), given_intensities) == ser(expected)


@given(st.text(max_size=300))
def test_string(text: str) -> None:
    assert E.StringEncoder().encode(text) == ser(T["std_msgs/msg/String"](data=text))


@given(
    stamps, frames, st.sampled_from([10, 20, 30, 40, 50]), st.text(), st.text(), st.text(), st.integers(0, 2**32 - 1)
)
def test_log(t: int, name: str, level: int, text: str, file: str, function: str, line: int) -> None:
    expected = T["rcl_interfaces/msg/Log"](
        stamp=time(t), level=level, name=name, msg=text, file=file, function=function, line=line
    )
    assert E.LogEncoder(name).encode(t, level, text, file=file, function=function, line=line) == ser(expected)


@given(
    stamps,
    st.lists(st.tuples(stamps, st.text(), st.sampled_from(["IDLE", "RUNNING", "SUCCESS", "FAILURE"])), max_size=5),
)
def test_behavior_tree_log(t: int, events: list[tuple[int, str, str]]) -> None:
    rows = [(et, node, "IDLE", status) for et, node, status in events]
    change = T["nav2_msgs/msg/BehaviorTreeStatusChange"]
    expected = T["nav2_msgs/msg/BehaviorTreeLog"](
        timestamp=time(t),
        event_log=[
            change(timestamp=time(et), node_name=node, previous_status=prev, current_status=cur)
            for et, node, prev, cur in rows
        ],
    )
    assert E.BehaviorTreeLogEncoder().encode(t, rows) == ser(expected)


@given(stamps, frames, st.sampled_from([1, 2]), st.text(), st.text(), st.lists(floats, min_size=7, max_size=7))
def test_contact(t: int, frame: str, event: int, robot: str, world: str, v: list[float]) -> None:
    expected = T["twin_msgs/msg/Contact"](
        header=header(t, frame),
        event=event,
        robot_collision=robot,
        world_collision=world,
        position=point(*v[:3]),
        normal=vec(*v[3:6]),
        depth_m=v[6],
    )
    data = E.ContactEncoder(frame).encode(
        t, event, robot_collision=robot, world_collision=world, position_m=v[:3], normal=v[3:6], depth_m=v[6]
    )
    assert data == ser(expected)


@given(stamps, frames, st.lists(floats, min_size=3, max_size=3), cov, st.booleans())
def test_pose_with_covariance_stamped(t: int, frame: str, v: list[float], c: list[float], per_call: bool) -> None:
    x, y, yaw = v
    if not math.isfinite(yaw):
        yaw = 1.0
    covariance = np.array(c)
    if per_call:
        data = E.PoseWithCovarianceStampedEncoder(frame).encode(t, x, y, yaw, covariance)
    else:
        data = E.PoseWithCovarianceStampedEncoder(frame, covariance=covariance).encode(t, x, y, yaw)
    expected = T["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=header(t, frame),
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=planar(x, y, yaw), covariance=covariance),
    )
    assert data == ser(expected)


@given(stamps, frames, st.lists(floats, min_size=3, max_size=3))
def test_pose_stamped(t: int, frame: str, v: list[float]) -> None:
    x, y, yaw = v
    if not math.isfinite(yaw):
        yaw = 0.0
    expected = T["geometry_msgs/msg/PoseStamped"](header=header(t, frame), pose=planar(x, y, yaw))
    assert E.PoseStampedEncoder(frame).encode(t, x, y, yaw) == ser(expected)


@settings(max_examples=60)
@given(stamps, frames, st.integers(0, 40), st.booleans(), st.randoms(use_true_random=False))
def test_path(t: int, frame: str, n: int, full: bool, rnd: Any) -> None:
    rng = np.random.default_rng(rnd.randint(0, 2**32))
    poses = rng.normal(size=(n, 7 if full else 3))
    stamped = T["geometry_msgs/msg/PoseStamped"]
    msgs = [stamped(header=header(t, frame), pose=pose7(p) if full else planar(*p)) for p in poses]
    expected = T["nav_msgs/msg/Path"](header=header(t, frame), poses=msgs)
    assert E.PathEncoder(frame).encode(t, poses) == ser(expected)


@settings(max_examples=60)
@given(stamps, frames, st.integers(0, 300), st.randoms(use_true_random=False))
def test_particle_cloud(t: int, frame: str, n: int, rnd: Any) -> None:
    rng = np.random.default_rng(rnd.randint(0, 2**32))
    poses = rng.normal(size=(n, 3))
    weights = rng.random(n)
    particle = T["nav2_msgs/msg/Particle"]
    expected = T["nav2_msgs/msg/ParticleCloud"](
        header=header(t, frame),
        particles=[particle(pose=planar(*p), weight=w) for p, w in zip(poses, weights, strict=True)],
    )
    assert E.ParticleCloudEncoder(frame).encode(t, poses, weights) == ser(expected)


@settings(max_examples=40)
@given(
    stamps,
    frames,
    st.integers(0, 30),
    st.integers(0, 30),
    st.floats(0.25, 1.0, width=32),
    st.randoms(use_true_random=False),
)
def test_occupancy_grid(t: int, frame: str, width: int, height: int, res: float, rnd: Any) -> None:
    rng = np.random.default_rng(rnd.randint(0, 2**32))
    cells = rng.choice(np.array([-1, 0, 50, 100], dtype=np.int8), size=(height, width))
    origin = (rng.normal(), rng.normal(), rng.normal())
    meta = T["nav_msgs/msg/MapMetaData"](
        map_load_time=time(t), resolution=res, width=width, height=height, origin=planar(*origin)
    )
    expected = T["nav_msgs/msg/OccupancyGrid"](header=header(t, frame), info=meta, data=cells.reshape(-1))
    assert E.OccupancyGridEncoder(frame, res, width, height, origin).encode(t, cells) == ser(expected)


def test_wrong_sizes_raise_bag_errors_naming_the_encoder() -> None:
    with pytest.raises(BagError, match="360 beams got 10"):
        E.ScanEncoder(
            "base_scan",
            angle_min_rad=0,
            angle_max_rad=6.28,
            angle_increment_rad=0.0175,
            time_increment_s=0,
            scan_time_s=0.2,
            range_min_m=0.12,
            range_max_m=3.5,
            samples=360,
        ).encode(0, np.zeros(10, np.float32))
    with pytest.raises(BagError, match="2 joints"):
        E.JointStateEncoder(["a", "b"]).encode(0, [1.0], [2.0])
    with pytest.raises(BagError, match="2 frame pairs needs as many poses of 7 values, got 1"):
        E.TFEncoder([("a", "b"), ("b", "c")]).encode(0, [(0, 0, 0, 0, 0, 0, 1)])
    with pytest.raises(BagError, match="pose_covariance needs 36"):
        E.OdometryEncoder().encode(0, 0, 0, 0, 0, 0, np.zeros(6))
    with pytest.raises(BagError, match="4x3 cells got 11"):
        E.OccupancyGridEncoder("map", 0.05, 4, 3).encode(0, np.zeros(11, np.int8))


@given(
    stamps,
    frames,
    st.lists(floats, min_size=3, max_size=3),
    st.integers(0, 10**12),
    st.integers(0, 10**12),
    st.integers(0, 32767),
    st.floats(width=32, allow_nan=False),
)
def test_navigation_feedback(
    t: int, frame: str, v: list[float], nav_ns: int, eta_ns: int, recoveries: int, remaining: float
) -> None:
    x, y, yaw = v
    if not math.isfinite(yaw):
        yaw = 0.0
    duration = T["builtin_interfaces/msg/Duration"]
    expected = T["twin_msgs/msg/NavigationFeedback"](
        current_pose=T["geometry_msgs/msg/PoseStamped"](header=header(t, frame), pose=planar(x, y, yaw)),
        navigation_time=duration(sec=nav_ns // 10**9, nanosec=nav_ns % 10**9),
        estimated_time_remaining=duration(sec=eta_ns // 10**9, nanosec=eta_ns % 10**9),
        number_of_recoveries=recoveries,
        distance_remaining=remaining,
    )
    data = E.NavigationFeedbackEncoder(frame).encode(t, (x, y, yaw), (nav_ns, eta_ns), recoveries, remaining)
    assert data == ser(expected)


def _marker(t: int, frame: str, marker_id: int, kind: int, action: int, p: Any, s: Any, c: Any, text: str) -> Any:
    return T["visualization_msgs/msg/Marker"](
        header=header(t, frame),
        ns="obstacles",
        id=marker_id,
        type=kind,
        action=action,
        pose=pose7(p),
        scale=vec(*s),
        color=T["std_msgs/msg/ColorRGBA"](r=c[0], g=c[1], b=c[2], a=c[3]),
        lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
        frame_locked=False,
        points=[],
        colors=[],
        texture_resource="",
        texture=T["sensor_msgs/msg/CompressedImage"](header=header(0, ""), format="", data=np.zeros(0, dtype=np.uint8)),
        uv_coordinates=[],
        text=text,
        mesh_resource="",
        mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8)),
        mesh_use_embedded_materials=False,
    )


@given(
    stamps,
    frames,
    st.lists(
        st.tuples(
            st.integers(min_value=0, max_value=2**31 - 1),
            st.sampled_from([E.MarkerArrayEncoder.CUBE, E.MarkerArrayEncoder.CYLINDER]),
            st.lists(floats, min_size=7, max_size=7),
            st.lists(floats, min_size=3, max_size=3),
            st.lists(st.floats(min_value=0.0, max_value=1.0, width=32), min_size=4, max_size=4),
            st.text(max_size=12),
        ),
        max_size=4,
    ),
)
def test_marker_array(t: int, frame: str, markers: list[Any]) -> None:
    expected = T["visualization_msgs/msg/MarkerArray"](
        markers=[_marker(t, frame, 0, 0, 3, (0.0,) * 6 + (1.0,), (0.0,) * 3, (0.0,) * 4, "")]
        + [_marker(t, frame, i, k, 0, p, s, c, text) for i, k, p, s, c, text in markers]
    )
    assert E.MarkerArrayEncoder(frame).encode(t, markers) == ser(expected)


@settings(max_examples=40, deadline=None)
@given(
    t=stamps,
    frame=frames,
    w=st.integers(1, 7),
    h=st.integers(1, 5),
    encoding=st.sampled_from(["rgb8", "mono8", "32FC1"]),
)
def test_image(t: int, frame: str, w: int, h: int, encoding: str) -> None:
    rng = np.random.default_rng(w * 10 + h)
    if encoding == "32FC1":
        pixels: Any = rng.uniform(0.0, 5.0, (h, w)).astype(np.float32)
        pixels[0, 0] = np.inf
        data = np.frombuffer(pixels.tobytes(), dtype=np.uint8)
        step = 4 * w
    else:
        channels = 3 if encoding == "rgb8" else 1
        pixels = rng.integers(0, 256, (h, w, channels), dtype=np.uint8)
        data = pixels.reshape(-1)
        step = channels * w
    expected = T["sensor_msgs/msg/Image"](
        header=header(t, frame), height=h, width=w, encoding=encoding, is_bigendian=0, step=step, data=data
    )
    assert E.ImageEncoder(frame, width=w, height=h, encoding=encoding).encode(t, pixels) == ser(expected)


def test_image_of_the_wrong_size_is_refused() -> None:
    with pytest.raises(BagError, match="12 bytes got 6"):
        E.ImageEncoder("cam", width=2, height=2, encoding="rgb8").encode(0, np.zeros(6, np.uint8))


@settings(max_examples=40, deadline=None)
@given(t=stamps, frame=frames, w=st.integers(1, 4000), h=st.integers(1, 4000), f=st.floats(1.0, 5000.0))
def test_camera_info(t: int, frame: str, w: int, h: int, f: float) -> None:
    K = (f, 0.0, (w + 1) / 2, 0.0, f, (h + 1) / 2, 0.0, 0.0, 1.0)
    P = (f, 0.0, (w + 1) / 2, 0.0, 0.0, f, (h + 1) / 2, 0.0, 0.0, 0.0, 1.0, 0.0)
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    expected = T["sensor_msgs/msg/CameraInfo"](
        header=header(t, frame),
        height=h,
        width=w,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=np.array(K),
        r=np.eye(3).reshape(-1),
        p=np.array(P),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )
    assert E.CameraInfoEncoder(frame, width=w, height=h, K=K, P=P).encode(t) == ser(expected)


@settings(max_examples=40, deadline=None)
@given(t=stamps, frame=frames, fmt=st.text(max_size=30), data=st.binary(max_size=40))
def test_compressed_image(t: int, frame: str, fmt: str, data: bytes) -> None:
    expected = T["sensor_msgs/msg/CompressedImage"](
        header=header(t, frame), format=fmt, data=np.frombuffer(data, dtype=np.uint8)
    )
    assert E.CompressedImageEncoder(frame, format=fmt).encode(t, data) == ser(expected)


@settings(max_examples=30, deadline=None)
@given(t=stamps, frame=frames, w=st.integers(1, 5), h=st.integers(1, 4), dense=st.booleans())
def test_point_cloud2(t: int, frame: str, w: int, h: int, dense: bool) -> None:
    fields = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("rgb", 16, 7, 1)]
    data = np.random.default_rng(w * h).integers(0, 256, w * h * 32, dtype=np.uint8)
    point_fields = [T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=c) for n, o, d, c in fields]
    expected = T["sensor_msgs/msg/PointCloud2"](
        header=header(t, frame),
        height=h,
        width=w,
        fields=point_fields,
        is_bigendian=False,
        point_step=32,
        row_step=32 * w,
        data=data,
        is_dense=dense,
    )
    enc = E.PointCloud2Encoder(frame, width=w, height=h, fields=fields, point_step=32, is_dense=dense)
    assert enc.encode(t, data.tobytes()) == ser(expected)
