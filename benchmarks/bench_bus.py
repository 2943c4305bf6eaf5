"""In-process delivery cost of the node graph: one `publish` reaching its subscribers, no serialisation.

Prints JSON: microseconds per publish with 0, 1 and 4 no-op subscribers (built-in nodes' path, no
type check), with 1 subscriber through a user node's checked publisher, and the cost of building
an `Encoded` message as built-in nodes do. The issue's budget: delivery <= 0.5 us per message.

    python benchmarks/bench_bus.py [--messages 200000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.msgs import Twist
from twin.node import Encoded, Node
from twin.sim.executor import Executor


class _Talker(Node):
    builtin = True

    def __init__(self, name: str, msg_type: type | str) -> None:
        super().__init__(name)
        self.pub = self.create_publisher(msg_type, "/chatter", 10)


class _Listener(Node):
    builtin = True

    def __init__(self, name: str, *, raw: bool) -> None:
        super().__init__(name)
        self.create_subscription("geometry_msgs/msg/Twist", "/chatter", lambda msg: None, 10, raw=raw)


class _UserTalker(Node):  # not built-in: publishes through the type-checked path
    def __init__(self) -> None:
        super().__init__("user_talker")
        self.pub = self.create_publisher(Twist, "/chatter", 10)


def _per_publish_us(publish, msg, n: int, repeat: int) -> float:  # type: ignore[no-untyped-def]
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(n):
            publish(msg)
        best = min(best, time.perf_counter() - start)
    return best / n * 1e6


def _graph(subscribers: int, *, user: bool = False) -> tuple[Executor, object]:
    ex = Executor(1_000_000)
    talker: _Talker | _UserTalker = _UserTalker() if user else _Talker("talker", "geometry_msgs/msg/Twist")
    ex.add_node(talker)
    for i in range(subscribers):
        ex.add_node(_Listener(f"listener{i}", raw=True))
    return ex, talker.pub.publish


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--messages", type=int, default=200_000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    n, repeat = args.messages, args.repeat
    msg = Encoded((lambda: b"", (), (0.1, 0.2)))
    result: dict[str, object] = {}
    for subs in (0, 1, 4):
        _, publish = _graph(subs)
        result[f"publish_{subs}_subscribers_us"] = round(_per_publish_us(publish, msg, n, repeat), 3)
    _, publish = _graph(1, user=True)
    result["user_publish_1_subscriber_us"] = round(_per_publish_us(publish, Twist(), n, repeat), 3)
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(n):
            Encoded((bytes, (), None))
        best = min(best, time.perf_counter() - start)
    result["encoded_message_build_us"] = round(best / n * 1e6, 3)
    result["budget_us"] = 0.5
    result["python"] = sys.version.split()[0]
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
