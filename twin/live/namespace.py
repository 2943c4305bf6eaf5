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
"""

from __future__ import annotations

__all__ = ["NamespaceView"]


class NamespaceView:
    """Which of a fleet's topics a client is served, and under which names, for the robot under `namespace`.

    Args:
        namespace: The robot's namespace (`robot1`, `/fleet/robot2/`; slashes at either end ignored).
    """

    def __init__(self, namespace: str) -> None:
        self.namespace = namespace.strip("/")
        self._prefix = f"/{self.namespace}/"

    def served_as(self, topic: str) -> str | None:
        """The name `topic` is served under (None: it is another robot's, not served)."""
        if topic.startswith(self._prefix):
            return "/" + topic[len(self._prefix) :]
        if topic.count("/") == 1:  # under no namespace: the world's (/clock, /rosout, a prefixed fleet's /tf)
            return topic
        return None
