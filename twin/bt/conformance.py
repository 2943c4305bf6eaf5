"""Run recorded BT.CPP conformance cases and compare the engine with them.

A case (see `../shared/bt_conformance/README.md`) holds a tree, scripts for its scripted leaves, a
number of ticks with the (wall-clock) sleep before each, and what BT.CPP 4.8.2 did: per tick the
root status, every status transition and every leaf call, and the root blackboard at the end.

The runner provides the scripted node types: `Leaf` (a stateful action), `Cond` (a condition) and
the case's `node_types`. It takes sleeps as simulated time on the tree's clock, so BT.CPP's timer
events between ticks happen at the start of the next tick; the comparison therefore puts a tick's
`between_*` events in front of its own for wall-time cases, as the rules say.

Comparison rules: the number of ticks and each root status exactly; transitions and leaf calls as
ordered lists; an expected error only needs an error on that tick (nothing after it is compared;
an error on the first tick before anything ran is also met by refusing to load the tree);
the blackboard must have the same keys, strings equal exactly, numbers and booleans numerically,
`null` meaning an entry without a value.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from twin.bt.factory import BehaviorTreeFactory
from twin.bt.node import ConditionNode, NodeConfig, StatefulActionNode, TreeNode
from twin.bt.ports import PortSpec, bidirectional_port, input_port, output_port
from twin.bt.status import NodeKind, NodeStatus
from twin.bt.tree import ManualClock, StatusListener
from twin.bt.values import PortType
from twin.core.errors import TreeError

__all__ = [
    "CaseResult",
    "CaseRun",
    "ConformanceCase",
    "LeafCallRecorder",
    "ScriptedAction",
    "ScriptedCondition",
    "Step",
    "check_case",
    "compare_run",
    "load_case",
    "run_case",
    "scripted_node_class",
]

_NS_PER_MS: Final = 1_000_000
MODES: Final = ("once", "exactly_once")


@dataclasses.dataclass(frozen=True, kw_only=True, slots=True)
class Step:
    """One scripted step: the status to return and the outputs to write first."""

    status: NodeStatus
    outputs: Mapping[str, Any]


@dataclasses.dataclass(frozen=True, kw_only=True, slots=True)
class ScriptedType:
    """A scripted node type of a case (`node_types`)."""

    kind: NodeKind
    ports: tuple[PortSpec, ...]


@dataclasses.dataclass(frozen=True, kw_only=True)
class ConformanceCase:
    """A conformance case file.

    Attributes:
        expected: per mode (`once`, `exactly_once`), the expected trace and blackboard.
    """

    path: Path
    id: str
    name: str
    description: str
    xml: str
    xml_v3: str | None
    main_tree: str | None
    node_types: Mapping[str, ScriptedType]
    leaf_scripts: Mapping[str, tuple[Step, ...]]
    ticks: int
    sleep_before_tick_ms: tuple[int, ...]
    wall_time: bool
    tick_mode: str
    expected: Mapping[str, tuple[tuple[Mapping[str, Any], ...], Mapping[str, Any] | None]]


def _fail(path: Path, problem: str) -> TreeError:
    return TreeError(f"{path}: {problem}")


def _parse_step(path: Path, leaf: str, raw: Any) -> Step:
    if isinstance(raw, str):
        raw = {"status": raw}
    if not isinstance(raw, dict) or raw.get("status") not in ("SUCCESS", "FAILURE", "RUNNING"):
        raise _fail(
            path, f"leaf_scripts[{leaf!r}]: a step is 'SUCCESS', 'FAILURE', 'RUNNING' or an object with 'status'"
        )
    outputs = raw.get("outputs", {})
    if not isinstance(outputs, dict):
        raise _fail(path, f"leaf_scripts[{leaf!r}]: 'outputs' must be an object")
    return Step(status=NodeStatus[raw["status"]], outputs=dict(outputs))


def _parse_type(path: Path, name: str, raw: Any) -> ScriptedType:
    if not isinstance(raw, dict) or raw.get("kind") not in ("action", "condition"):
        raise _fail(path, f"node_types[{name!r}]: 'kind' must be 'action' or 'condition'")
    makers = {"input": input_port, "output": output_port, "inout": bidirectional_port}
    ports: list[PortSpec] = []
    for port, spec in dict(raw.get("ports", {})).items():
        direction = spec if isinstance(spec, str) else spec.get("direction") if isinstance(spec, dict) else None
        if direction not in makers:
            raise _fail(path, f"node_types[{name!r}].ports[{port!r}]: direction must be input, output or inout")
        default = spec.get("default") if isinstance(spec, dict) else None
        if default is None:
            ports.append(makers[direction](port))
        elif direction == "output":
            ports.append(output_port(port, None, str(default)))
        else:
            ports.append(makers[direction](port, None, str(default)))
    kind = NodeKind.ACTION if raw["kind"] == "action" else NodeKind.CONDITION
    return ScriptedType(kind=kind, ports=tuple(ports))


def load_case(path: Path) -> ConformanceCase:
    """Read a case file.

    Raises:
        TreeError: If the file is unreadable or a required field is missing or malformed.
    """
    path = Path(path)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise _fail(path, "file not found") from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as err:
        raise _fail(path, f"not a readable JSON case ({err})") from None
    if not isinstance(raw, dict):
        raise _fail(path, "a case is a JSON object")
    for key in ("id", "xml", "ticks", "expected_trace"):
        if key not in raw:
            raise _fail(path, f"missing key {key!r}")
    try:
        return _case_from_json(path, raw)
    except TreeError:
        raise
    except (ValueError, TypeError, AttributeError) as err:  # a field of the wrong JSON type
        raise _fail(
            path, f"not a case in the format of bt_conformance/README.md ({type(err).__name__}: {err})"
        ) from None


def _whole(path: Path, field: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(path, f"{field} must be a whole number, got {value!r}")
    return value


def _case_from_json(path: Path, raw: dict[str, Any]) -> ConformanceCase:
    ticks = _whole(path, "ticks", raw["ticks"])
    if ticks < 1:
        raise _fail(path, f"ticks must be at least 1, got {ticks}")
    sleeps = tuple(
        _whole(path, "each entry of sleep_before_tick_ms", ms) for ms in raw.get("sleep_before_tick_ms", [0] * ticks)
    )
    if len(sleeps) != ticks:
        raise _fail(path, f"sleep_before_tick_ms has {len(sleeps)} entries for {ticks} ticks")
    tick_mode = str(raw.get("tick_mode", "once"))
    expected = {tick_mode: (tuple(raw["expected_trace"]), raw.get("expected_blackboard"))}
    for mode, alt in dict(raw.get("alt_modes", {})).items():
        expected[mode] = (tuple(alt.get("expected_trace", ())), alt.get("expected_blackboard"))
    return ConformanceCase(
        path=path,
        id=str(raw["id"]),
        name=str(raw.get("name", "")),
        description=str(raw.get("description", "")),
        xml=str(raw["xml"]),
        xml_v3=raw.get("xml_v3"),
        main_tree=raw.get("main_tree"),
        node_types={name: _parse_type(path, name, spec) for name, spec in dict(raw.get("node_types") or {}).items()},
        leaf_scripts={
            leaf: tuple(_parse_step(path, leaf, step) for step in steps)
            for leaf, steps in dict(raw.get("leaf_scripts") or {}).items()
        },
        ticks=ticks,
        sleep_before_tick_ms=sleeps,
        wall_time=bool(raw.get("wall_time", False)),
        tick_mode=tick_mode,
        expected=expected,
    )


class LeafCallRecorder:
    """Collects the transitions and leaf calls of one tick, and the steps taken per node path."""

    def __init__(self) -> None:
        self.transitions: list[list[str]] = []
        self.calls: list[list[Any]] = []
        self.counters: dict[str, int] = {}

    def on_status(self, t_ns: int, path: str, uid: int, prev: NodeStatus, new: NodeStatus) -> None:
        """Record a status change (a tree listener)."""
        self.transitions.append([path, prev.name, new.name])


class _Scripted:
    """The behaviour shared by scripted actions and conditions: take the next step of the path's script."""

    def __init__(self, node: TreeNode, scripts: Mapping[str, tuple[Step, ...]], recorder: LeafCallRecorder) -> None:
        self._node = node
        self._scripts = scripts
        self._recorder = recorder
        manifest = node.config.manifest
        self._inputs = tuple(name for name, spec in manifest.ports.items() if spec.is_input) if manifest else ()

    def step(self, call: str) -> NodeStatus:
        node = self._node
        path = node.full_path
        steps = self._scripts.get(path)
        if not steps:
            msg = f"no leaf script for {path!r}"
            raise TreeError(msg)
        index = self._recorder.counters.get(path, 0)
        self._recorder.counters[path] = index + 1
        step = steps[min(index, len(steps) - 1)]
        record: list[Any] = [path, call, step.status.name]
        if self._inputs:
            record.append({name: _read_string(node, name) for name in self._inputs})
        for port, value in step.outputs.items():
            node.set_output(port, value)
        self._recorder.calls.append(record)
        return step.status

    def halted(self) -> None:
        self._recorder.calls.append([self._node.full_path, "onHalted"])


def _read_string(node: TreeNode, port: str) -> str | None:
    ok, value = node.read_input(port, PortType.STRING)
    return value if ok else None


class ScriptedAction(StatefulActionNode):
    """A `Leaf` (or action `node_types` entry) that plays its script."""

    def __init__(
        self, name: str, config: NodeConfig, scripts: Mapping[str, tuple[Step, ...]], recorder: LeafCallRecorder
    ) -> None:
        super().__init__(name, config)
        self._play = _Scripted(self, scripts, recorder)

    def on_start(self) -> NodeStatus:
        """Take the next step."""
        return self._play.step("onStart")

    def on_running(self) -> NodeStatus:
        """Take the next step."""
        return self._play.step("onRunning")

    def on_halted(self) -> None:
        """Record the halt."""
        self._play.halted()


class ScriptedCondition(ConditionNode):
    """A `Cond` (or condition `node_types` entry) that plays its script."""

    def __init__(
        self, name: str, config: NodeConfig, scripts: Mapping[str, tuple[Step, ...]], recorder: LeafCallRecorder
    ) -> None:
        super().__init__(name, config)
        self._play = _Scripted(self, scripts, recorder)

    def tick(self) -> NodeStatus:
        """Take the next step."""
        return self._play.step("tick")


def scripted_node_class(base: type[TreeNode], ports: tuple[PortSpec, ...], name: str = "") -> type[TreeNode]:
    """A subclass of `ScriptedAction` or `ScriptedCondition` with the given ports."""

    def provided_ports(cls: type) -> tuple[PortSpec, ...]:
        return ports

    return type(name or base.__name__, (base,), {"provided_ports": classmethod(provided_ports)})


def scripted_factory(case: ConformanceCase, recorder: LeafCallRecorder) -> BehaviorTreeFactory:
    """A factory with BT.CPP's built-ins and the case's scripted node types."""
    factory = BehaviorTreeFactory()
    types = {
        "Leaf": ScriptedType(kind=NodeKind.ACTION, ports=()),
        "Cond": ScriptedType(kind=NodeKind.CONDITION, ports=()),
    }
    types.update(case.node_types)
    for name, scripted in types.items():
        base: type[TreeNode] = ScriptedAction if scripted.kind is NodeKind.ACTION else ScriptedCondition
        factory.register_node_type(scripted_node_class(base, scripted.ports), name, case.leaf_scripts, recorder)
    return factory


@dataclasses.dataclass(frozen=True, kw_only=True)
class CaseRun:
    """What the engine did: the trace (same shape as the case's) and the root blackboard."""

    trace: tuple[Mapping[str, Any], ...]
    blackboard: Mapping[str, Any] | None
    load_error: str | None = None


def _json_value(value: Any) -> Any:
    if value is None or isinstance(value, str | bool | int | float):
        return int(value) if isinstance(value, NodeStatus) else value
    if isinstance(value, deque | list | tuple):
        return [_json_value(item) for item in value]
    if isinstance(value, dict):
        return {str(key): _json_value(item) for key, item in value.items()}
    return repr(value)


def run_case(
    case: ConformanceCase,
    *,
    mode: str = "once",
    v3: bool = False,
    listeners: Sequence[StatusListener] = (),
    tick_listener: Callable[[int, NodeStatus], None] | None = None,
) -> CaseRun:
    """Run a case's tree (its `xml`, or `xml_v3` when `v3`) with scripted leaves.

    Args:
        case: the case.
        mode: `once` (tickOnce) or `exactly_once` (tickExactlyOnce).
        v3: run `xml_v3` instead of `xml`.
        listeners: extra status listeners (e.g. a `StatusLog`).
        tick_listener: called with (t_ns, root status) after each completed tick.

    Raises:
        TreeError: If `v3` is asked for a case without `xml_v3`, or the mode is unknown.
    """
    if mode not in MODES:
        msg = f"unknown tick mode {mode!r}; use one of {', '.join(MODES)}"
        raise TreeError(msg)
    xml = case.xml_v3 if v3 else case.xml
    if xml is None:
        msg = f"{case.path}: the case has no xml_v3"
        raise TreeError(msg)
    recorder = LeafCallRecorder()
    factory = scripted_factory(case, recorder)
    clock = ManualClock()
    try:
        tree = factory.create_tree_from_text(
            xml, main_tree=case.main_tree, clock=clock, source=f"{case.path.name}:{'xml_v3' if v3 else 'xml'}"
        )
    except TreeError as err:
        return CaseRun(trace=(), blackboard=None, load_error=str(err))
    tree.add_listener(recorder.on_status)
    for listener in listeners:
        tree.add_listener(listener)
    tick = tree.tick_once if mode == "once" else tree.tick_exactly_once
    trace: list[Mapping[str, Any]] = []
    for index in range(case.ticks):
        clock.advance(case.sleep_before_tick_ms[index] * _NS_PER_MS)
        recorder.transitions, recorder.calls = [], []
        entry: dict[str, Any] = {"tick": index + 1}
        try:
            status = tick()
        except TreeError as err:
            entry.update(root_status=None, transitions=recorder.transitions, leaf_calls=recorder.calls, error=str(err))
            trace.append(entry)
            break
        entry.update(root_status=status.name, transitions=recorder.transitions, leaf_calls=recorder.calls)
        trace.append(entry)
        if tick_listener is not None:
            tick_listener(tree.now_ns, status)
    board = {key: _json_value(entry.value) for key, entry in tree.root_blackboard.items()}
    return CaseRun(trace=tuple(trace), blackboard=board)


def _same_value(expected: Any, got: Any) -> bool:
    if expected is None or got is None:
        return expected is None and got is None
    if isinstance(expected, str) or isinstance(got, str):
        return isinstance(expected, str) and isinstance(got, str) and expected == got
    if isinstance(expected, int | float) and isinstance(got, int | float):
        return math.isclose(float(expected), float(got), rel_tol=1e-9, abs_tol=1e-12)
    return bool(expected == got)


def _events(tick: Mapping[str, Any], key: str, merge_between: bool) -> list[list[Any]]:
    items = [list(item) for item in tick.get(key, [])]
    if merge_between:
        items = [list(item) for item in tick.get("between_" + key, [])] + items
    return items


def _first_mismatch(expected: Sequence[Any], got: Sequence[Any]) -> str:
    for index, (exp, actual) in enumerate(zip(expected, got, strict=False)):
        if exp != actual:
            return f"item {index + 1}: expected {json.dumps(exp)}, got {json.dumps(actual)}"
    if len(expected) > len(got):
        return f"missing {json.dumps(expected[len(got) :])}"
    return f"unexpected {json.dumps(list(got[len(expected) :]))}"


def _error_before_anything_ran(expected_trace: Sequence[Mapping[str, Any]]) -> bool:
    """Whether BT.CPP failed on the first tick before any node changed status or any leaf was called.

    That is how a recording shows a tree BT.CPP refused to load (or one whose first node threw at
    once); an engine that refuses to load such a tree behaves the same for its user.
    """
    if not expected_trace:
        return False
    first = expected_trace[0]
    return first.get("error") is not None and not first.get("transitions") and not first.get("leaf_calls")


def compare_run(case: ConformanceCase, run: CaseRun, *, mode: str = "once") -> list[str]:
    """The differences between a run and the case's expectations (empty when they agree)."""
    if mode not in case.expected:
        return [f"the case has no expectations for tick mode {mode!r}"]
    expected_trace, expected_board = case.expected[mode]
    if run.load_error is not None:
        if _error_before_anything_ran(expected_trace):
            return []  # refused earlier than BT.CPP, with nothing run before: the same for a user
        return [f"the tree did not load: {run.load_error}"]
    problems: list[str] = []
    if len(run.trace) != len(expected_trace) and not any(t.get("error") for t in expected_trace):
        problems.append(f"number of ticks: expected {len(expected_trace)}, got {len(run.trace)}")
    for index, (exp, got) in enumerate(zip(expected_trace, run.trace, strict=False)):
        tag = f"tick {index + 1}"
        if exp.get("error") is not None:
            if not got.get("error"):
                problems.append(f"{tag}: expected an error ({exp['error']!r}), the engine reported none")
            return problems
        if got.get("error"):
            problems.append(f"{tag}: unexpected error: {got['error']}")
            return problems
        if exp.get("root_status") != got.get("root_status"):
            problems.append(f"{tag}: root status expected {exp.get('root_status')}, got {got.get('root_status')}")
        for key, label in (("transitions", "transitions"), ("leaf_calls", "leaf calls")):
            want = _events(exp, key, case.wall_time)
            have = _events(got, key, case.wall_time)
            if want != have:
                problems.append(f"{tag}: {label} differ at {_first_mismatch(want, have)}")
    if len(run.trace) < len(expected_trace) and not problems:
        problems.append(f"number of ticks: expected {len(expected_trace)}, got {len(run.trace)}")
    if expected_board is not None and run.blackboard is not None:
        want_keys, have_keys = set(expected_board), set(run.blackboard)
        if want_keys != have_keys:
            missing, unexpected = sorted(want_keys - have_keys), sorted(have_keys - want_keys)
            problems.append(f"blackboard keys differ: missing {missing}, unexpected {unexpected}")
        for key in sorted(want_keys & have_keys):
            if not _same_value(expected_board[key], run.blackboard[key]):
                problems.append(f"blackboard[{key!r}]: expected {expected_board[key]!r}, got {run.blackboard[key]!r}")
    return problems


@dataclasses.dataclass(frozen=True, kw_only=True)
class CaseResult:
    """The outcome of one case: its problems (empty when it passed) for `xml` and, if any, `xml_v3`."""

    case: ConformanceCase
    problems: tuple[str, ...]
    v3_problems: tuple[str, ...] | None

    @property
    def passed(self) -> bool:
        """True when `xml` (and `xml_v3`, when present) reproduce the expectations."""
        return not self.problems and not self.v3_problems

    @property
    def first_difference(self) -> str:
        """The first problem, as one line."""
        if self.problems:
            return self.problems[0]
        if self.v3_problems:
            return f"xml_v3: {self.v3_problems[0]}"
        return ""


def check_case(case: ConformanceCase, *, mode: str = "once", check_v3: bool = True) -> CaseResult:
    """Run a case (and its `xml_v3`, which must give the same result) and compare."""
    problems = compare_run(case, run_case(case, mode=mode), mode=mode)
    v3_problems = None
    if check_v3 and case.xml_v3 is not None:
        v3_problems = tuple(compare_run(case, run_case(case, mode=mode, v3=True), mode=mode))
    return CaseResult(case=case, problems=tuple(problems), v3_problems=v3_problems)
