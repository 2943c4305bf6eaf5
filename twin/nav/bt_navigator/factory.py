"""Nav2's behaviour-tree nodes registered into the engine's factory, as BT.CPP plugins register them.

- `nav2_factory(services=None)`: a factory with BT.CPP's built-ins, Nav2's control nodes
  (`control_nodes`), and Nav2's leaves (`leaves`) implemented against `services` (None: declared
  with their ports only, enough to validate and show a tree).
- `register_nav2_controls(factory)`, `declare_nav2_leaves(factory)`, `register_nav2_leaves(factory,
  services)`: the parts on their own.
- `unloaded_behavior(bt_xml, servers)`: a behaviour leaf whose action behavior_server does not load.
- `unimplemented_leaf(bt_xml)`: a Nav2 node the tree uses that the twin declares but does not run.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from twin.bt.factory import BehaviorTreeFactory
from twin.bt.loader import TreeParser
from twin.nav.bt_navigator.control_nodes import register_nav2_controls
from twin.nav.bt_navigator.leaves import IMPLEMENTED, NavigationServices, register_nav2_leaves
from twin.nav.bt_navigator.tree_nodes import NAV2_DECORATORS, NAV2_LEAVES, declare_nav2_leaves

__all__ = [
    "BEHAVIOR_LEAVES",
    "declare_nav2_leaves",
    "nav2_factory",
    "register_nav2_controls",
    "register_nav2_leaves",
    "unimplemented_leaf",
    "unloaded_behavior",
]


def nav2_factory(services: NavigationServices | None = None) -> BehaviorTreeFactory:
    """A factory with BT.CPP's built-ins, Nav2's controls, and Nav2's leaves.

    Args:
        services: The navigation servers the leaves call; None declares the leaves with their
            ports only (trees validate and show, but cannot be created).
    """
    factory = BehaviorTreeFactory()
    register_nav2_controls(factory)
    if services is not None:
        register_nav2_leaves(factory, services)
    declare_nav2_leaves(factory)
    return factory


# Nav2's behaviour leaves and the behavior_server action each calls unless its `server_name` names another.
BEHAVIOR_LEAVES = {
    "Spin": "spin",
    "BackUp": "backup",
    "DriveOnHeading": "drive_on_heading",
    "Wait": "wait",
    "AssistedTeleop": "assisted_teleop",
}


def unloaded_behavior(bt_xml: Path, servers: Mapping[str, object]) -> str | None:
    """Where the navigator tree calls a behaviour action behavior_server does not load, as one line; None if none.

    Nav2 Humble's behaviour leaves wait for their action server when the tree is created and throw
    without it, so the navigator cannot start a tree whose `<BackUp>` calls a `backup` that
    `behavior_plugins` leaves out. A `server_name` taken from the blackboard is not judged.
    """
    parser = TreeParser(nav2_factory())
    parser.load_file(Path(bt_xml))
    for root, _ in parser.tree_roots.values():
        for element in root.iter():
            default = BEHAVIOR_LEAVES.get(element.type_name)
            if default is None:
                continue
            server = element.attrs.get("server_name") or default
            if server.strip().startswith("{") or server in servers:
                continue
            return (
                f"{element.location}: <{element.type_name}> calls the {server!r} action, which behavior_server "
                f"does not load (behavior_plugins: {', '.join(servers) or 'none'}), so Nav2 cannot create this "
                f"tree; add {server!r} to behavior_plugins with its plugin type, or take the node out of the tree"
            )
    return None


def unimplemented_leaf(bt_xml: Path) -> str | None:
    """Where the tree uses a Nav2 node the twin declares (its ports validate) but does not run, as one line.

    A NavigateToPose or NavigateThroughPoses client (the action the navigator itself serves) validates
    against the palette, and the navigator cannot create it.
    """
    parser = TreeParser(nav2_factory())
    parser.load_file(Path(bt_xml))
    nav2 = NAV2_LEAVES.keys() | NAV2_DECORATORS.keys()
    for root, _ in parser.tree_roots.values():
        for element in root.iter():
            if element.type_name in nav2 and element.type_name not in IMPLEMENTED:
                return (
                    f"{element.location}: <{element.type_name}> is a Nav2 node the twin knows the ports of but "
                    "does not run; use a tree without it, such as Nav2's navigate_to_pose_w_replanning_and_recovery.xml"
                )
    return None
