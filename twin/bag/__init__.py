"""Layer 1: ROS 2 bags. Fast message encoders, the crash-safe recorder, readers and recovery.

The only package that imports rosbags and mcap. The simulation builds one encoder per topic and
hands its bytes to a `Recorder`; analysis reads bags back with `open_bag` and `read_messages`.

The reading side (readers, raw reader, provenance, recovery) loads on first use of its names, so a
run that only records does not import rosbags' bag readers.
"""

from typing import TYPE_CHECKING, Any

from twin.bag.encoders import (
    BehaviorTreeLogEncoder,
    CameraInfoEncoder,
    ClockEncoder,
    CompressedImageEncoder,
    ContactEncoder,
    ImageEncoder,
    ImuEncoder,
    JointStateEncoder,
    LogEncoder,
    MarkerArrayEncoder,
    MotorStateEncoder,
    NavigationFeedbackEncoder,
    OccupancyGridEncoder,
    OdometryEncoder,
    ParticleCloudEncoder,
    PathEncoder,
    PointCloud2Encoder,
    PoseStampedEncoder,
    PoseWithCovarianceStampedEncoder,
    ScanEncoder,
    StringEncoder,
    TFEncoder,
    TwistEncoder,
)
from twin.bag.profiles import DISTROS
from twin.bag.qos import (
    QOS_BEST_EFFORT,
    QOS_LATCHED,
    QOS_RELIABLE,
    QOS_ROSOUT,
    Durability,
    QosProfile,
    Reliability,
    default_qos,
)
from twin.bag.recorder import STORAGES, Recorder, TopicHandle

if TYPE_CHECKING:
    from twin.bag.provenance import read_provenance
    from twin.bag.raw import read_raw, require_readable
    from twin.bag.reader import (
        BagInfo,
        BagMessage,
        TopicInfo,
        message_definitions,
        open_bag,
        read_messages,
        robot_namespaces,
    )
    from twin.bag.recover import RecoveryReport, recover_bag

_LAZY = {
    "read_provenance": "twin.bag.provenance",
    "read_raw": "twin.bag.raw",
    "require_readable": "twin.bag.raw",
    "BagInfo": "twin.bag.reader",
    "BagMessage": "twin.bag.reader",
    "TopicInfo": "twin.bag.reader",
    "message_definitions": "twin.bag.reader",
    "open_bag": "twin.bag.reader",
    "read_messages": "twin.bag.reader",
    "robot_namespaces": "twin.bag.reader",
    "RecoveryReport": "twin.bag.recover",
    "recover_bag": "twin.bag.recover",
}

__all__ = [
    "DISTROS",
    "QOS_BEST_EFFORT",
    "QOS_LATCHED",
    "QOS_RELIABLE",
    "QOS_ROSOUT",
    "STORAGES",
    "BagInfo",
    "BagMessage",
    "BehaviorTreeLogEncoder",
    "CameraInfoEncoder",
    "ClockEncoder",
    "CompressedImageEncoder",
    "ContactEncoder",
    "Durability",
    "ImageEncoder",
    "ImuEncoder",
    "JointStateEncoder",
    "LogEncoder",
    "MarkerArrayEncoder",
    "MotorStateEncoder",
    "NavigationFeedbackEncoder",
    "OccupancyGridEncoder",
    "OdometryEncoder",
    "ParticleCloudEncoder",
    "PathEncoder",
    "PointCloud2Encoder",
    "PoseStampedEncoder",
    "PoseWithCovarianceStampedEncoder",
    "QosProfile",
    "Recorder",
    "RecoveryReport",
    "Reliability",
    "ScanEncoder",
    "StringEncoder",
    "TFEncoder",
    "TopicHandle",
    "TopicInfo",
    "TwistEncoder",
    "default_qos",
    "message_definitions",
    "open_bag",
    "read_messages",
    "read_provenance",
    "read_raw",
    "recover_bag",
    "require_readable",
    "robot_namespaces",
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        msg = f"module 'twin.bag' has no attribute {name!r}"
        raise AttributeError(msg)
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
