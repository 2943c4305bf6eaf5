"""The blackboard: typed entries shared by the nodes of a tree, with BT.CPP's remapping rules.

Each (sub)tree instance has its own `Blackboard`. A SubTree's blackboard looks a key up locally
first, then through its explicit remapping (`goal="{target}"` maps the subtree key `goal` to the
parent key `target`), then, with `_autoremap`, under the same name in the parent (keys starting
with `_` are never auto-remapped). A key starting with `@` always means the root blackboard.

An entry holds a value (`None` when it exists but is empty), the declared type of the first port
or value that created it, and a sequence number that counts writes (for `WasEntryUpdated`).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from twin.bt.values import ConversionError, PortType, copy_into, is_safe_cast, type_of_value
from twin.core.errors import TreeError

__all__ = ["Blackboard", "Entry"]


class Entry:
    """One blackboard entry: value (`None` = empty), declared type and write counter."""

    __slots__ = ("info", "seq", "value")

    def __init__(self, info: PortType, value: Any = None) -> None:
        self.info = info
        self.value = value
        self.seq = 0

    def __repr__(self) -> str:
        return f"Entry({self.value!r}, type={self.info.name}, seq={self.seq})"


def _matches(info: PortType, value: Any) -> bool:
    """True when a value has the entry's declared type (Python containers match by class)."""
    if type_of_value(value) == info:
        return True
    py_type = info.py_type
    return info.kind in ("custom", "sequence", "enum") and py_type is not None and isinstance(value, py_type)


class Blackboard:
    """Key-value storage of one (sub)tree instance.

    Args:
        parent: the blackboard of the enclosing tree, for a SubTree's blackboard.
    """

    __slots__ = ("_autoremap", "_parent", "_remap", "_storage", "_writes")

    def __init__(self, parent: Blackboard | None = None) -> None:
        self._storage: dict[str, Entry] = {}
        self._parent = parent
        self._remap: dict[str, str] = {}
        self._autoremap = False
        # one write counter for a blackboard and every blackboard below it
        self._writes: list[int] = parent._writes if parent is not None else [0]

    @property
    def version(self) -> int:
        """How many writes this blackboard's tree of blackboards has taken (`set`, `unset`, new entries)."""
        return self._writes[0]

    def note_write(self) -> None:
        """Count a write made to an entry in place (a script assigning to it)."""
        self._writes[0] += 1

    # -- structure -----------------------------------------------------------------------------

    @property
    def parent(self) -> Blackboard | None:
        """The enclosing tree's blackboard, or None for the root."""
        return self._parent

    def root(self) -> Blackboard:
        """The root blackboard of the tree."""
        board = self
        while board._parent is not None:
            board = board._parent
        return board

    def enable_auto_remapping(self, enabled: bool) -> None:
        """Look keys up in the parent under the same name (SubTree `_autoremap`)."""
        self._autoremap = enabled

    def add_subtree_remapping(self, internal: str, external: str) -> None:
        """Map the subtree key `internal` to the parent key `external`."""
        self._remap.setdefault(internal, external)

    # -- entries -------------------------------------------------------------------------------

    def get_entry(self, key: str) -> Entry | None:
        """The entry a key refers to, following `@`, remapping and auto-remapping; None if absent."""
        if key[:1] == "@":
            return self.root().get_entry(key[1:])
        entry = self._storage.get(key)
        if entry is not None:
            return entry
        parent = self._parent
        if parent is not None:
            external = self._remap.get(key)
            if external is not None:
                return parent.get_entry(external)
            if self._autoremap and key[:1] != "_":
                return parent.get_entry(key)
        return None

    def create_entry(self, key: str, info: PortType) -> Entry:
        """Create (or find) the entry of a key with a declared type.

        Raises:
            TreeError: If the entry exists with another strongly-typed type.
        """
        if key[:1] == "@":
            if "@" in key[1:]:
                msg = f"blackboard key {key!r}: character '@' used multiple times"
                raise TreeError(msg)
            return self.root()._create_entry_impl(key[1:], info)
        return self._create_entry_impl(key, info)

    def _create_entry_impl(self, key: str, info: PortType) -> Entry:
        entry = self._storage.get(key)
        if entry is not None:
            prev = entry.info
            if prev != info and prev.strongly_typed and info.strongly_typed:
                msg = (
                    f"blackboard entry [{key}]: once declared, the type of a port shall not change; "
                    f"previously declared type [{prev.name}], current type [{info.name}]"
                )
                raise TreeError(msg)
            return entry
        parent = self._parent
        external = self._remap.get(key)
        if external is not None and parent is not None:
            return parent._create_entry_impl(external, info)
        if self._autoremap and key[:1] != "_" and parent is not None:
            return parent._create_entry_impl(key, info)
        entry = Entry(info)
        self._storage[key] = entry
        self._writes[0] += 1
        return entry

    def set(self, key: str, value: Any, *, as_any: bool = False) -> None:
        """Write a value (BT.CPP `Blackboard::set<T>`, with T the value's Python type).

        A new entry takes the value's type, except that a string creates an untyped entry. An
        untyped entry takes the type of the first typed value written to it. A typed entry accepts
        a string it can parse, or a number it can hold exactly; anything else is an error.

        Args:
            key: the key; `@key` writes to the root blackboard.
            value: the value; `None` stores an empty value (only with `as_any`).
            as_any: write a type-erased value as BT.CPP's `set<BT::Any>` does (SetBlackboard):
                no string parsing and no numeric narrowing.

        Raises:
            TreeError: If the entry is typed and the value does not fit.
        """
        if key[:1] == "@":
            self.root().set(key[1:], value, as_any=as_any)
            return
        self._writes[0] += 1
        entry = self._storage.get(key)
        if entry is None:
            info = PortType.ANY if (isinstance(value, str) and not as_any) or value is None else type_of_value(value)
            entry = self._create_entry_impl(key, info)
            entry.value = value
            entry.seq += 1
            return
        if not entry.info.strongly_typed:
            entry.info = PortType.BT_ANY if as_any else type_of_value(value)
            entry.value = value
            entry.seq += 1
            return
        prev = entry.info
        if value is not None and not _matches(prev, value):
            fits = False
            if isinstance(value, str) and not as_any:
                try:
                    parsed = prev.parse(value)
                except ConversionError as err:
                    msg = f"blackboard entry [{key}] of type [{prev.name}]: cannot convert {value!r}: {err}"
                    raise TreeError(msg) from None
                if parsed is not None:
                    fits, value = True, parsed
            if not fits and not as_any and isinstance(value, int | float) and is_safe_cast(prev, value):
                fits = True
            if not fits:
                msg = (
                    f"Blackboard::set({key}): once declared, the type of a port shall not change; "
                    f"previously declared type [{prev.name}], current type [{type_of_value(value).name}]"
                )
                raise TreeError(msg)
        if as_any:
            entry.value = value
        else:
            try:
                entry.value = copy_into(value, entry.value)
            except ConversionError as err:
                msg = f"blackboard entry [{key}]: cannot store {value!r} over {entry.value!r}: {err}"
                raise TreeError(msg) from None
        entry.seq += 1

    def get(self, key: str) -> Any:
        """The value of a key.

        Raises:
            TreeError: If the key is missing or its entry is empty.
        """
        entry = self.get_entry(key)
        if entry is None:
            msg = f"blackboard: missing key [{key}]"
            raise TreeError(msg)
        if entry.value is None:
            msg = f"blackboard: entry [{key}] hasn't been initialized, yet"
            raise TreeError(msg)
        return entry.value

    def unset(self, key: str) -> None:
        """Remove a local entry (nothing happens when there is none)."""
        if self._storage.pop(key, None) is not None:
            self._writes[0] += 1

    def keys(self) -> list[str]:
        """The keys stored in this blackboard (not those reached through remapping)."""
        return list(self._storage)

    def items(self) -> Iterator[tuple[str, Entry]]:
        """The local entries."""
        return iter(self._storage.items())

    def to_dict(self) -> dict[str, Any]:
        """The local values by key (`None` for empty entries)."""
        return {key: entry.value for key, entry in self._storage.items()}

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and self.get_entry(key) is not None

    def __getitem__(self, key: str) -> Any:
        return self.get(key)

    def __setitem__(self, key: str, value: Any) -> None:
        self.set(key, value)

    def __repr__(self) -> str:
        return f"Blackboard({self.to_dict()!r})"
