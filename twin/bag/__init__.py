"""Layer 1: ROS 2 bags. Fast message encoders, the crash-safe recorder, readers and recovery.

The only package that imports rosbags and mcap. The simulation builds one encoder per topic and
hands its bytes to a `Recorder`; analysis reads bags back with `open_bag` and `read_messages`.
"""

from twin.bag.encoders import (
    BehaviorTreeLogEncoder,
    ClockEncoder,
    ContactEncoder,
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
    PoseStampedEncoder,
    PoseWithCovarianceStampedEncoder,
    ScanEncoder,
    StringEncoder,
    TFEncoder,
    TwistEncoder,
)
from twin.bag.profiles import DISTROS
from twin.bag.provenance import read_provenance
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
from twin.bag.raw import read_raw
from twin.bag.reader import BagInfo, BagMessage, TopicInfo, message_definitions, open_bag, read_messages
from twin.bag.recorder import STORAGES, Recorder, TopicHandle
from twin.bag.recover import RecoveryReport, recover_bag

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
    "ClockEncoder",
    "ContactEncoder",
    "Durability",
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
]
