"""Small helpers shared by the behaviour-tree tests."""

from __future__ import annotations


def v4(body: str, extra: str = "") -> str:
    """A BTCPP_format 4 document whose MainTree is `body`, plus extra top-level elements."""
    return (
        f'<root BTCPP_format="4" main_tree_to_execute="MainTree"><BehaviorTree ID="MainTree">{body}</BehaviorTree>'
        f"{extra}</root>"
    )
