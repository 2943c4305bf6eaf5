"""Layer 1: a behaviour-tree engine that loads BehaviorTree.CPP XML and ticks it as BT.CPP does (v4 as 4.x, v3 as 3.8).

Import what you use from here:

    from twin.bt import BehaviorTreeFactory, ManualClock, NodeStatus

Custom nodes subclass `SyncActionNode`, `StatefulActionNode`, `ConditionNode`, `DecoratorNode` or
`ControlNode` and declare their ports with `input_port`, `output_port` and `bidirectional_port`.
"""

from twin.bt.blackboard import Blackboard
from twin.bt.factory import PLUGIN_GROUP, BehaviorTreeFactory
from twin.bt.node import (
    ConditionNode,
    ControlNode,
    DecoratorNode,
    NodeConfig,
    NodeManifest,
    StatefulActionNode,
    SyncActionNode,
    TickError,
    TreeNode,
)
from twin.bt.ports import PortSpec, bidirectional_port, input_port, output_port
from twin.bt.status import NodeKind, NodeStatus, PortDirection
from twin.bt.tree import ManualClock, StatusListener, Tree
from twin.bt.values import PortType

__all__ = [
    "PLUGIN_GROUP",
    "BehaviorTreeFactory",
    "Blackboard",
    "ConditionNode",
    "ControlNode",
    "DecoratorNode",
    "ManualClock",
    "NodeConfig",
    "NodeKind",
    "NodeManifest",
    "NodeStatus",
    "PortDirection",
    "PortSpec",
    "PortType",
    "StatefulActionNode",
    "StatusListener",
    "SyncActionNode",
    "TickError",
    "Tree",
    "TreeNode",
    "bidirectional_port",
    "input_port",
    "output_port",
]
