"""Load the scenario's own nodes, as a launch file's `Node(package=..., executable=...)` entries start them.

`plugin: module:Class` imports `module` (a file beside the scenario is importable, as are installed
modules) and takes `Class`; a bare `plugin: name` is an entry point of the `twin.nodes` group, which
installed packages use to offer nodes. The class is constructed with no arguments inside a launch
context that carries the entry's name, namespace, parameters and remappings.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

from twin.core.config import key_location, suggest
from twin.core.errors import ConfigError, TwinError
from twin.node import LaunchArguments, Node, launch_context
from twin.sim.scenario import NodeSpec, Scenario

__all__ = ["ENTRY_POINT_GROUP", "constructing_node", "known_node_plugins", "load_nodes"]

ENTRY_POINT_GROUP = "twin.nodes"


def known_node_plugins() -> dict[str, str]:
    """Entry-point names of the `twin.nodes` group and what each points at (`module:Class`)."""
    import importlib.metadata  # tens of ms to import: only when a scenario names its own nodes

    return {ep.name: ep.value for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}


@contextlib.contextmanager
def _importable(folder: Path | None) -> Iterator[None]:
    if folder is None:
        yield
        return
    entry = str(folder)
    added = entry not in sys.path
    if added:
        sys.path.insert(0, entry)
    try:
        yield
    finally:
        if added:
            with contextlib.suppress(ValueError):
                sys.path.remove(entry)


def _node_classes(module: ModuleType) -> list[str]:
    return [
        name
        for name, value in vars(module).items()
        if inspect.isclass(value) and issubclass(value, Node) and value is not Node
    ]


def _resolve_class(spec: NodeSpec, where: str, folder: Path | None) -> type:
    plugin = spec.plugin.strip()
    known = known_node_plugins()
    if ":" not in plugin:
        if plugin not in known:
            hint = suggest(plugin, list(known)) or (
                "; give `module:Class` (a module beside the scenario file works) or install a package "
                f"offering it in the {ENTRY_POINT_GROUP!r} entry-point group"
            )
            msg = f"{where}.plugin: no node plugin {plugin!r}{hint}"
            raise ConfigError(msg)
        plugin = known[plugin]
    module_name, _, class_name = plugin.partition(":")
    with _importable(folder):
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as err:
            if err.name is not None and module_name.startswith(err.name):
                choices = [*known, *(v.partition(":")[0] for v in known.values())]
                if folder is not None:
                    choices += [p.stem for p in folder.glob("*.py")]
                hint = suggest(module_name, choices)
                place = f" (looked beside the scenario in {folder} and in installed packages)" if folder else ""
                msg = f"{where}.plugin: module {module_name!r} not found{place}{hint}"
                raise ConfigError(msg) from None
            msg = f"{where}.plugin: importing {module_name!r} failed: {err}"
            raise ConfigError(msg) from None
        except TwinError:
            raise
        except (Exception, SystemExit) as err:
            msg = f"{where}.plugin: importing {module_name!r} raised {type(err).__name__}: {err}"
            raise ConfigError(msg) from None
    cls = getattr(module, class_name, None)
    if cls is None:
        msg = (
            f"{where}.plugin: module {module_name!r} has no {class_name!r}{suggest(class_name, _node_classes(module))}"
        )
        raise ConfigError(msg)
    if not (inspect.isclass(cls) and issubclass(cls, Node)):
        msg = f"{where}.plugin: {plugin} is not a twin.node.Node subclass; derive it from twin.node.Node"
        raise ConfigError(msg)
    return cls


def _construct(cls: type, arguments: LaunchArguments, folder: Path | None) -> Any:
    """Call a user node's constructor (`constructing_node` finds a thread inside it by this frame)."""
    with launch_context(arguments), _importable(folder):
        return cls()


def constructing_node(ident: int) -> str | None:
    """The class of the user node whose constructor thread `ident` is running (in `load_nodes`), or None.

    A watchdog reads it from its own thread: a constructor that does not return is a node's fault,
    while the rest of a start-up (a large world, a first compile) may take as long as it takes.
    """
    frame = sys._current_frames().get(ident)
    while frame is not None:
        if frame.f_code is _construct.__code__:
            cls = frame.f_locals.get("cls")
            return getattr(cls, "__name__", "a node")
        frame = frame.f_back
    return None


def check_node_plugins(scenario: Scenario) -> None:
    """Import each `nodes:` entry's plugin and find its Node class, as `load_nodes` does, constructing none.

    Raises:
        ConfigError: As `load_nodes` for a plugin that does not import or is not a Node.
    """
    source = scenario.source_path
    folder = source.parent if source is not None else None
    for i, spec in enumerate(scenario.nodes):
        where = f"{key_location(source, f'nodes[{i}]')}: " if source is not None else ""
        _resolve_class(spec, f"{where}nodes[{i}]", folder)


def load_nodes(scenario: Scenario) -> list[Node]:
    """Construct the scenario's `nodes:` entries, in order.

    Raises:
        ConfigError: Naming the scenario file and the entry, if a plugin does not import, is not a
            Node, or its constructor fails.
    """
    source = scenario.source_path
    folder = source.parent if source is not None else None
    nodes: list[Node] = []
    for i, spec in enumerate(scenario.nodes):
        where = f"{key_location(source, f'nodes[{i}]')}: nodes[{i}]" if source is not None else f"nodes[{i}]"
        cls = _resolve_class(spec, where, folder)
        arguments = LaunchArguments(
            name=spec.name,
            namespace=spec.namespace,
            parameters=dict(spec.parameters),
            remappings=dict(spec.remappings),
        )
        try:
            node = _construct(cls, arguments, folder)
        except ConfigError as err:
            msg = f"{where}: {err}"
            raise ConfigError(msg) from None
        except TwinError:
            raise
        except (Exception, SystemExit) as err:  # sys.exit() in a constructor too: the node's fault
            msg = f"{where}: constructing {cls.__name__} raised {type(err).__name__}: {err}"
            raise ConfigError(msg) from None
        if "_namespace" not in vars(node):  # Node.__init__ never ran: nothing of the node is set up
            msg = (
                f"{where}: {cls.__name__}.__init__ does not call super().__init__('node_name'); call it first, "
                "as an rclpy node does"
            )
            raise ConfigError(msg)
        nodes.append(node)
    return nodes
