"""`LookForObject`: the TurtleBot3 behaviour demos' vision node (sea-bass/turtlebot3_behavior_demos).

The node waits for the first camera image taken after it started, thresholds it in HSV for its
target colour and runs OpenCV's SimpleBlobDetector on the mask: SUCCESS when a blob is found,
FAILURE when none is, or when no image arrives within the demos' 3 s image timeout. As in the
demos' C++ node it has no ports: the colour is a node parameter (`mission.target_color`), one of
the demos' thresholds (OpenCV hue 0..180):

| colour | H | S | V |
|---|---|---|---|
| red | 160-180 | 220-255 | 0-255 |
| green | 40-90 | 220-255 | 0-255 |
| blue | 100-150 | 220-255 | 0-255 |

Blob detection as the demos configure it: area 100 to 100000 px, filtered by area only,
thresholdStep 50.

The camera is anything with `want(on)` and `latest()` (`ImageSource`): a lazy camera renders only
while someone wants its images, as a Gazebo camera with no subscriber does not render.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from twin.bt.node import NodeConfig, StatefulActionNode
from twin.bt.ports import PortSpec
from twin.bt.status import NodeStatus

if TYPE_CHECKING:
    from twin.bt.factory import BehaviorTreeFactory

__all__ = [
    "HSV_THRESHOLDS",
    "IMAGE_TIMEOUT_NS",
    "ImageSlot",
    "ImageSource",
    "LookForObject",
    "find_blobs",
    "register_vision_nodes",
]

_log = logging.getLogger(__name__)

HSV_THRESHOLDS: dict[str, tuple[tuple[int, int, int], tuple[int, int, int]]] = {
    "red": ((160, 220, 0), (180, 255, 255)),
    "green": ((40, 220, 0), (90, 255, 255)),
    "blue": ((100, 220, 0), (150, 255, 255)),
}
"""The demos' HSV bounds per colour (OpenCV: H in 0..180, S and V in 0..255)."""

IMAGE_TIMEOUT_NS = 3_000_000_000
"""The demos' image timeout: FAILURE when no image arrives within it."""


class ImageSource(Protocol):
    """A camera as `LookForObject` reads it."""

    def want(self, on: bool) -> None:
        """Ask for images (True) or stop asking (False); requests are counted."""
        ...

    def latest(self) -> tuple[int, NDArray[np.uint8]] | None:
        """The last image (stamp ns, RGB (h, w, 3) or mono (h, w)), or None before the first."""
        ...


class ImageSlot:
    """Where a tree's vision nodes find the camera; filled in once the camera exists (or left empty)."""

    def __init__(self) -> None:
        self.source: ImageSource | None = None


def _detector() -> Any:
    import cv2

    params = cv2.SimpleBlobDetector.Params()
    params.minArea = 100
    params.maxArea = 100000
    params.filterByArea = True
    params.filterByColor = False
    params.filterByInertia = False
    params.filterByConvexity = False
    params.filterByCircularity = False
    params.thresholdStep = 50
    return cv2.SimpleBlobDetector.create(params)


def find_blobs(image: NDArray[np.uint8], color: str) -> list[tuple[float, float, float]]:
    """Blobs of `color` in an RGB image as the demos find them: (u, v, diameter) in pixels.

    Raises:
        KeyError: If `color` is not one of `HSV_THRESHOLDS`.
    """
    import cv2

    low, high = HSV_THRESHOLDS[color]
    if image.ndim == 2:  # a mono camera: no hue, so no colour matches (as cv_bridge to bgr8 would give)
        image = np.repeat(image[:, :, None], 3, axis=2)
    hsv = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2HSV)
    mask = cv2.inRange(hsv, low, high)
    keypoints = _detector().detect(mask)
    return [(float(k.pt[0]), float(k.pt[1]), float(k.size)) for k in keypoints]


class LookForObject(StatefulActionNode):
    """Look for a blob of the target colour in the next camera image (see the module's doc)."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """No ports: the target colour is a node parameter, as in the demos."""
        return ()

    def __init__(
        self, name: str, config: NodeConfig, slot: ImageSlot, target_color: str, log: logging.Logger = _log
    ) -> None:
        super().__init__(name, config)
        self._log = log
        if target_color not in HSV_THRESHOLDS:
            msg = f"target_color {target_color!r} is not one of {', '.join(HSV_THRESHOLDS)}"
            raise ValueError(msg)
        self._slot = slot
        self.target_color = target_color
        self._start_ns = 0
        self._wanting = False
        self.failure: tuple[int, str] | None = None
        """(tree time, why) of this node's last FAILURE, for the run's summary."""
        self.found: list[tuple[float, float, float]] = []
        """The blobs of the last image looked at."""

    def _want(self, on: bool) -> None:
        source = self._slot.source
        if source is not None and on != self._wanting:
            source.want(on)
            self._wanting = on

    def on_start(self) -> NodeStatus:
        """Start waiting for an image taken from now on."""
        self._start_ns = self.now_ns()
        if self._slot.source is None:
            self.failure = (self._start_ns, f"{self.full_path}: no camera image (the scenario's camera is off)")
            self._log.warning("%s: no camera: enable sensors.camera in the scenario", self.full_path)
            return NodeStatus.FAILURE
        self._want(True)
        return self.on_running()

    def on_running(self) -> NodeStatus:
        """Look at the first image since the start, or wait for one until the timeout."""
        source = self._slot.source
        latest = source.latest() if source is not None else None
        now = self.now_ns()
        if latest is None or latest[0] < self._start_ns:
            if now - self._start_ns < IMAGE_TIMEOUT_NS:
                return NodeStatus.RUNNING
            self._want(False)
            self.failure = (now, f"{self.full_path}: Image timeout exceeded")
            self._log.info("%s: Image timeout exceeded", self.full_path)
            return NodeStatus.FAILURE
        self._want(False)
        self.found = find_blobs(latest[1], self.target_color)
        if self.found:
            self._log.info("%s: found %d %s object(s)", self.full_path, len(self.found), self.target_color)
            return NodeStatus.SUCCESS
        self.failure = (now, f"{self.full_path}: no {self.target_color} object in view")
        self._log.info("%s: no %s object in view", self.full_path, self.target_color)
        return NodeStatus.FAILURE

    def on_halted(self) -> None:
        """Stop asking for images."""
        self._want(False)


def register_vision_nodes(
    factory: BehaviorTreeFactory, *, slot: ImageSlot, target_color: str = "blue", log: logging.Logger = _log
) -> None:
    """Register `LookForObject` looking for `target_color` in the images of `slot`'s camera (its lines to `log`)."""
    factory.register_node_type(LookForObject, "LookForObject", slot, target_color, log)
