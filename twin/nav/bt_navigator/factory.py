"""Nav2's behaviour-tree nodes registered into the engine's factory, as BT.CPP plugins register them.

- `nav2_factory(services=None)`: a factory with BT.CPP's built-ins, Nav2's control nodes
  (`control_nodes`), and Nav2's leaves (`leaves`) implemented against `services` (None: declared
  with their ports only, enough to validate and show a tree).
- `register_nav2_controls(factory)`, `declare_nav2_leaves(factory)`, `register_nav2_leaves(factory,
  services)`: the parts on their own.
"""

from __future__ import annotations

from twin.bt.factory import BehaviorTreeFactory
from twin.nav.bt_navigator.control_nodes import register_nav2_controls
from twin.nav.bt_navigator.leaves import NavigationServices, register_nav2_leaves
from twin.nav.bt_navigator.tree_nodes import declare_nav2_leaves

__all__ = ["declare_nav2_leaves", "nav2_factory", "register_nav2_controls", "register_nav2_leaves"]


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
