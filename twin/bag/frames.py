"""Gazebo's `frame_prefix`: a robot's frames named under its namespace (`robot1/odom`) on one shared `/tf`.

robot_state_publisher's `frame_prefix` parameter and Gazebo's sensor and drive plugins with a
prefixed frame name rename every frame a robot publishes, in its TF and in its messages' headers,
so that several robots share one TF tree. The frames every robot shares keep their names: `map`
(the one map all robots localise in: each robot's AMCL publishes `map -> robot1/odom`) and
`world`; an empty frame id stays empty.

An encoder (`twin.bag.encoders`) made inside `frame_prefix("robot1")` writes its frame ids
prefixed; the prefix is read once, when the encoder is made, so encoding costs nothing more. The
nodes themselves keep computing in their own robot's frames, as Nav2 does with prefixed frame
parameters: nothing in a robot's stack looks up another robot's frames.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator

__all__ = ["SHARED_FRAMES", "current_frame_prefix", "frame_prefix", "prefixed"]

#: Frames every robot shares: never prefixed.
SHARED_FRAMES = frozenset({"", "map", "world"})

_PREFIX: contextvars.ContextVar[str] = contextvars.ContextVar("twin_frame_prefix", default="")


@contextlib.contextmanager
def frame_prefix(prefix: str) -> Iterator[None]:
    """Encoders made inside this block write their robot frames as `<prefix>/<frame>` (`""`: as given)."""
    token = _PREFIX.set(prefix.strip("/"))
    try:
        yield
    finally:
        _PREFIX.reset(token)


def current_frame_prefix() -> str:
    """The prefix in force (`""`: none)."""
    return _PREFIX.get()


def prefixed(frame: str, prefix: str | None = None) -> str:
    """`frame` under `prefix` (default: the one in force); shared frames and already prefixed ones as given."""
    p = _PREFIX.get() if prefix is None else prefix.strip("/")
    if not p or frame in SHARED_FRAMES or frame.startswith(f"{p}/"):
        return frame
    return f"{p}/{frame}"
