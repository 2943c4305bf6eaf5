"""The behaviour-tree tests' rig (scripted leaves, recorded calls), for Nav2's control nodes."""

from tests.unit.bt.conftest import rig

__all__ = ["rig"]
