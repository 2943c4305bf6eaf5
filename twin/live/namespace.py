"""One robot of a fleet in the live view (`--namespace NS`): its topics under a single robot's names, and the world's.

A fleet's run or bag holds each robot's topics under its namespace (`/robot1/scan`, `/robot1/tf`...)
and the world's under none (`/clock`, `/rosout`, and with `tf: {mode: frame_prefix}` the shared
`/tf` and `/tf_static`). A client shown every robot at once gets one `odom`, one `base_footprint`
per robot in as many TF trees, which a 3D panel cannot tell apart. Picking one robot serves its
topics with the namespace taken off (`/robot1/scan` as `/scan`, `/robot1/tf` as `/tf`): what a
one-robot run serves, so the shipped Foxglove layout shows that robot as it shows the thesis's.
The world's topics are served as they are; the other robots' are not served. A world topic of
the same name and type as one of the robot's (the shared `/tf` of a prefixed fleet has no twin
under the namespace, so only in a bag made otherwise) is served on the same channel.

A fleet whose frames are prefixed (`tf: {mode: frame_prefix}`, as Gazebo's `frame_prefix` names
them: `robot1/odom`, `robot1/base_footprint` on one shared `/tf`) is served as one robot's too:
the robot's prefix is taken off every frame id its messages carry (`robot1/base_scan` as
`base_scan`), and of the shared `/tf` and `/tf_static` only the robot's own transforms and the
world's (`map`...) are served, not the other robots'. The shipped layout then finds
`base_footprint` as in a one-robot run. Such messages are decoded and encoded again; the others
are served byte for byte.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["NamespaceView"]

_log = logging.getLogger(__name__)

_TF = "tf2_msgs/msg/TFMessage"
_FRAME_FIELDS = ("frame_id", "child_frame_id")

# How to find a type's frame ids: per field holding one or leading to one, (name, kind, nested plan),
# kind "frame" (a string), "msg" (a message) or "seq" (an array or sequence of messages).
_Plan = tuple[tuple[str, str, Any], ...]


class NamespaceView:
    """Which of a fleet's topics a client is served, and under which names, for the robot under `namespace`.

    Args:
        namespace: The robot's namespace (`robot1`, `/fleet/robot2/`; slashes at either end ignored).
    """

    def __init__(self, namespace: str, *, frame_prefix: bool = False, robots: Sequence[str] = ()) -> None:
        self.namespace = namespace.strip("/")
        self._prefix = f"/{self.namespace}/"
        self.frame_prefix = frame_prefix
        """Whether the fleet's frames carry their robot's prefix (`robot1/odom`), to be taken off."""
        self._robots = sorted({r.strip("/") for r in (*robots, self.namespace)}, key=len, reverse=True)
        self._plans: dict[str, _Plan] = {}

    def served_as(self, topic: str) -> str | None:
        """The name `topic` is served under (None: it is another robot's, not served)."""
        if topic.startswith(self._prefix):
            return "/" + topic[len(self._prefix) :]
        if topic.count("/") == 1:  # under no namespace: the world's (/clock, /rosout, a prefixed fleet's /tf)
            return topic
        return None

    def rewriter(self, msgtype: str, store: Typestore) -> Callable[[bytes], bytes | None] | None:
        """What a served topic's messages become: None when served as they are (no frame to rename).

        Otherwise a function of a message's CDR bytes: the bytes to serve, or None for a TF message
        that holds only other robots' transforms (not served).
        """
        if not self.frame_prefix:
            return None
        plan = () if msgtype == _TF else self._plan(msgtype, store)
        if msgtype != _TF and not plan:
            return None

        def rewrite(data: bytes) -> bytes | None:
            if msgtype == _TF:
                return self._own_transforms(data, store)
            msg = store.deserialize_cdr(data, msgtype)
            self._strip(msg, plan)
            return bytes(store.serialize_cdr(msg, msgtype))

        warned = False

        def served(data: bytes) -> bytes | None:
            nonlocal warned
            try:
                return rewrite(data)
            except Exception as err:  # rosbags' decoder raises several kinds on damaged bytes
                if not warned:  # a damaged message (a recovered bag) is served as it is, not fatal
                    warned = True
                    _log.warning("a %s message does not decode (%s): served as recorded", msgtype, err)
                return data

        return served

    def robot_of(self, frame: str) -> str | None:
        """The robot whose prefixed frame this is (`robot1/odom`: robot1; nested: the longest), or None (`map`)."""
        name = frame.lstrip("/")
        return next((r for r in self._robots if name.startswith(f"{r}/")), None)

    def own_frame(self, frame: str) -> str:
        """The frame as a one-robot run names it: the robot's own prefix taken off."""
        name = frame.lstrip("/")
        return name[len(self.namespace) + 1 :] if self.robot_of(name) == self.namespace else frame

    def _own_transforms(self, data: bytes, store: Typestore) -> bytes | None:
        msg: Any = store.deserialize_cdr(data, _TF)
        if not msg.transforms:
            return data  # nothing of anyone's: as it is
        kept = []
        for tf in msg.transforms:
            robots = {self.robot_of(tf.header.frame_id), self.robot_of(tf.child_frame_id)} - {None}
            if robots <= {self.namespace}:
                tf.header.frame_id = self.own_frame(tf.header.frame_id)
                tf.child_frame_id = self.own_frame(tf.child_frame_id)
                kept.append(tf)
        if not kept:
            return None
        msg.transforms = kept
        return bytes(store.serialize_cdr(msg, _TF))

    def _plan(self, msgtype: str, store: Typestore) -> _Plan:
        plan = self._plans.get(msgtype)
        if plan is not None:
            return plan
        from rosbags.interfaces import Nodetype

        self._plans[msgtype] = ()  # (a type that holds itself ends here)
        steps: list[tuple[str, str, Any]] = []
        fields: list[tuple[str, tuple[Any, Any]]] = list(store.fielddefs[msgtype][1])
        for name, (kind, detail) in fields:
            if kind == Nodetype.BASE and name in _FRAME_FIELDS and detail[0] == "string":
                steps.append((name, "frame", None))
            elif kind == Nodetype.NAME and (inner := self._plan(str(detail), store)):
                steps.append((name, "msg", inner))
            elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.NAME:
                inner = self._plan(str(detail[0][1]), store)
                if inner:
                    steps.append((name, "seq", inner))
        plan = self._plans[msgtype] = tuple(steps)
        return plan

    def _strip(self, msg: Any, plan: _Plan) -> None:
        for name, kind, inner in plan:
            if kind == "frame":
                setattr(msg, name, self.own_frame(getattr(msg, name)))
            elif kind == "msg":
                self._strip(getattr(msg, name), inner)
            else:
                for item in getattr(msg, name):
                    self._strip(item, inner)
