"""Built-in leaves of BehaviorTree.CPP 4.x.

AlwaysSuccess, AlwaysFailure, Script, ScriptCondition, SetBlackboard, UnsetBlackboard, Sleep and
WasEntryUpdated.
"""

from __future__ import annotations

from twin.bt.node import (
    ConditionNode,
    NodeConfig,
    StatefulActionNode,
    SyncActionNode,
    TreeNode,
    remapped_key,
    strip_pointer,
)
from twin.bt.ports import PortSpec, bidirectional_port, input_port
from twin.bt.script import Script, parse_script, script_truth
from twin.bt.status import FAILURE, RUNNING, SUCCESS, NodeStatus
from twin.bt.ticking import TimerHandle
from twin.bt.values import ConversionError, PortType
from twin.core.errors import TreeError

__all__ = [
    "AlwaysFailureNode",
    "AlwaysSuccessNode",
    "EntryUpdatedAction",
    "ScriptCondition",
    "ScriptNode",
    "ScriptPort",
    "SetBlackboardNode",
    "SleepNode",
    "UnsetBlackboardNode",
]


class AlwaysSuccessNode(SyncActionNode):
    """Returns SUCCESS."""

    def tick(self) -> NodeStatus:
        """SUCCESS."""
        return SUCCESS


class AlwaysFailureNode(SyncActionNode):
    """Returns FAILURE."""

    def tick(self) -> NodeStatus:
        """FAILURE."""
        return FAILURE


class ScriptPort:
    """A script held in an input port: parsed once, and again only when its text changes.

    As in BT.CPP, an empty script is never parsed: `load()` then returns None (a `Script` does
    nothing; `ScriptCondition` and `Precondition` fail when ticked).
    """

    __slots__ = ("_node", "_port", "_script", "_source")

    def __init__(self, node: TreeNode, port: str) -> None:
        self._node = node
        self._port = port
        self._source = ""
        self._script: Script | None = None

    def load(self) -> Script | None:
        """The current script.

        Raises:
            TreeError: If the port cannot be read.
            ScriptSyntaxError: If the script does not parse.
        """
        ok, source = self._node.read_input(self._port, PortType.STRING)
        if not ok:
            msg = f"Missing port [{self._port}] in {self._node.registration_id}: {source}"
            raise TreeError(msg)
        if source != self._source:
            self._script = parse_script(source)
            self._source = source
        return self._script


class ScriptNode(SyncActionNode):
    """Run the script in `code`; always SUCCESS."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Code."""
        return (input_port("code", str, description="Piece of code that can be parsed", required=True),)

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._loader = ScriptPort(self, "code")
        self._loader.load()

    def tick(self) -> NodeStatus:
        """Run the script."""
        script = self._loader.load()
        if script is not None:
            script(self._env)
        return SUCCESS


class ScriptCondition(ConditionNode):
    """SUCCESS when the script in `code` is true."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Code."""
        return (
            input_port(
                "code", description="Piece of code that can be parsed. Must return false or true", required=True
            ),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._loader = ScriptPort(self, "code")
        self._loader.load()

    def tick(self) -> NodeStatus:
        """Evaluate the script."""
        script = self._loader.load()
        if script is None:
            raise TreeError("the condition script is empty")
        return SUCCESS if script_truth(script(self._env)) else FAILURE


class SetBlackboardNode(SyncActionNode):
    """Write `value` (a literal string, or a copy of `{entry}` with its type) into `output_key`."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Value and output_key."""
        return (
            input_port("value", description="Value to be written into the output_key", required=True),
            bidirectional_port(
                "output_key",
                description="Name of the blackboard entry where the value should be written",
                required=True,
            ),
        )

    def tick(self) -> NodeStatus:
        """Copy the value; FAILURE when the source entry is empty."""
        ok, output_key = self.read_input("output_key", PortType.STRING)
        if not ok:
            raise TreeError(f"missing port [output_key]: {output_key}")
        value_str = self._config.input_ports.get("value")
        if value_str is None:
            raise TreeError("missing port [value]")
        board = self._config.blackboard
        dst_entry = board.get_entry(output_key)
        source_key = strip_pointer(value_str)
        if source_key is not None:
            src_entry = board.get_entry(source_key)
            if src_entry is None:
                raise TreeError("Can't find the port referred by [value]")
            if dst_entry is None:
                board.create_entry(output_key, src_entry.info)
                dst_entry = board.get_entry(output_key)
            out_value = src_entry.value
        else:
            out_value = value_str
        if out_value is None:
            return FAILURE
        if dst_entry is not None and dst_entry.info != PortType.STRING and isinstance(out_value, str):
            try:
                out_value = dst_entry.info.parse(out_value, self._config.enums)
            except ConversionError as err:
                msg = f"Can't convert string [{out_value}] to type [{dst_entry.info.name}]: {err}"
                raise TreeError(msg) from None
        board.set(output_key, out_value, as_any=True)
        return SUCCESS


class UnsetBlackboardNode(SyncActionNode):
    """Remove the entry `key`; always SUCCESS."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Key."""
        return (input_port("key", str, description="Key of the entry to remove", required=True),)

    def tick(self) -> NodeStatus:
        """Remove the entry."""
        ok, key = self.read_input("key")
        if not ok:
            raise TreeError(f"missing input port [key]: {key}")
        self._config.blackboard.unset(key)
        return SUCCESS


class SleepNode(StatefulActionNode):
    """RUNNING for `msec` of simulation time, then SUCCESS."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Msec."""
        return (input_port("msec", PortType.UINT, required=True),)

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._waiting = False
        self._timer: TimerHandle | None = None

    def _on_timer(self, aborted: bool) -> None:
        if not aborted:
            self.emit_wake_up_signal()
        self._waiting = False

    def on_start(self) -> NodeStatus:
        """Start the timer (SUCCESS at once for 0 ms)."""
        ok, value = self.read_input("msec")
        if not ok:
            raise TreeError(f"Missing parameter [msec] in SleepNode: {value}")
        msec = int(value)
        if msec <= 0:
            return SUCCESS
        tree = self.tree
        if tree is None:
            raise TreeError("Sleep needs a tree (its timer runs on the tree's clock)")
        self.set_status(RUNNING)
        self._waiting = True
        self._timer = tree.timers.add(tree.now_ns + msec * 1_000_000, self._on_timer)
        return RUNNING

    def on_running(self) -> NodeStatus:
        """RUNNING until the timer fired."""
        return RUNNING if self._waiting else SUCCESS

    def on_halted(self) -> None:
        """Cancel the timer."""
        self._waiting = False
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None


class EntryUpdatedAction(SyncActionNode):
    """SUCCESS when the entry was written since the previous tick of this node."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Entry."""
        return (input_port("entry", PortType.BT_ANY, description="Entry to check", required=True),)

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._sequence_id = 0
        raw = config.input_ports.get("entry", "")
        if not raw:
            msg = f"Missing port 'entry' in {name}"
            raise TreeError(msg)
        self._entry_key = remapped_key("entry", raw) or raw

    def tick(self) -> NodeStatus:
        """Compare the entry's write counter with the one seen last time."""
        entry = self._config.blackboard.get_entry(self._entry_key)
        if entry is None:
            return FAILURE
        previous, self._sequence_id = self._sequence_id, entry.seq
        return SUCCESS if previous != entry.seq else FAILURE
