"""Two robots' bodies asked about each other: the shape pairs asked give what FCL over every shape gives.

`RobotBody.contacts_with` and `distance_to` place and ask FCL about only the pairs of shapes whose
bounding circles can touch (or beat the distance found so far). The reference here is FCL's own
broad phase over both robots' every shape (`_place` puts them all at the pose and updates the
tree), asked between the fast queries, so a shape the fast path left elsewhere would show too.
Where FCL's cap on contacts cuts the answer (bodies deep in each other), which contacts it keeps
depends on the order it asks pairs in; there both keep more than the cap, each a true contact.
"""

from __future__ import annotations

import math
import random

import fcl
import pytest

from twin.sim.scenario import default_scenario_path
from twin.world import load_robot
from twin.world.scene import RobotBody

MODELS = default_scenario_path().parent.parent / "sdf" / "models"

_Pose = tuple[float, float, float]


def _body(model: str) -> RobotBody:
    spec = load_robot(model, model_path=[MODELS])
    return RobotBody(spec.collisions, base_height_m=spec.base_height_m)


def _reference_distance(a: RobotBody, pose: _Pose, b: RobotBody, other: _Pose) -> float:
    a._place(*pose)
    b._place(*other)
    data = fcl.DistanceData()
    a._manager.distance(b._manager, data, fcl.defaultDistanceCallback)
    return max(0.0, float(data.result.min_distance))


def _reference_contacts(
    a: RobotBody, pose: _Pose, b: RobotBody, other: _Pose, cap: int = 8
) -> list[tuple[object, ...]]:
    a._place(*pose)
    b._place(*other)
    data = fcl.CollisionData(request=fcl.CollisionRequest(num_max_contacts=cap, enable_contact=True))
    a._manager.collide(b._manager, data, fcl.defaultCollisionCallback)
    out = []
    for c in data.result.contacts:
        mine, theirs = a.owner(c.o1), b.owner(c.o2)
        assert mine is not None and theirs is not None
        out.append((mine.name, theirs.name, max(0.0, float(c.penetration_depth)), tuple(float(v) for v in c.pos)))
    return sorted(out, key=repr)


def _contacts(a: RobotBody, pose: _Pose, b: RobotBody, other: _Pose) -> list[tuple[object, ...]]:
    return sorted(
        ((m.name, t.name, depth, point) for m, t, point, _, depth in a.contacts_with(pose, b, other)), key=repr
    )


def _same_contacts(fast: list[tuple[object, ...]], a: RobotBody, pose: _Pose, b: RobotBody, other: _Pose) -> None:
    reference = _reference_contacts(a, pose, b, other)
    if len(reference) <= 8:
        assert fast == reference
    else:
        # FCL stops once it holds more than the 8 asked for, after whichever pairs it asked first (two
        # bodies deep in each other): as many, each one of all the contacts there are.
        every = _reference_contacts(a, pose, b, other, cap=1000)
        assert len(fast) > 8
        assert set(fast) <= set(every)


@pytest.mark.parametrize(
    ("mine", "theirs"), [("turtlebot3_waffle", "turtlebot3_waffle"), ("turtlebot3_burger", "turtlebot3_waffle")]
)
def test_distances_and_contacts_between_two_robots_are_fcls_over_every_shape(mine: str, theirs: str) -> None:
    a, b = _body(mine), _body(theirs)
    rng = random.Random(7)
    touching = apart = capped = 0
    for _ in range(300):
        other = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-math.pi, math.pi))
        bearing = rng.uniform(-math.pi, math.pi)
        centres = rng.uniform(0.1, 0.5)
        pose = (other[0] + centres * math.cos(bearing), other[1] + centres * math.sin(bearing), rng.uniform(-4, 4))
        # The fast queries first (they leave shapes placed piecemeal), then the whole-body reference.
        fast_distance, fast_contacts = a.distance_to(pose, b, other), _contacts(a, pose, b, other)
        assert fast_distance == _reference_distance(a, pose, b, other)
        _same_contacts(fast_contacts, a, pose, b, other)
        touching += bool(fast_contacts)
        capped += len(fast_contacts) > 8
        apart += fast_distance > 0.0
        # Creeping: the same robot a hair further on (its near shapes move there), then the whole
        # body asked back at the pose before, then the reference at the new pose.
        crept = (pose[0] + 1e-7, pose[1], pose[2])
        crept_contacts = _contacts(a, crept, b, other)
        assert _reference_distance(a, pose, b, other) == fast_distance
        _same_contacts(crept_contacts, a, crept, b, other)
        # The yes-or-no question a drive asks at each step of a contact: the same answer, with
        # both bodies' shapes left at other poses by the queries before (it places what it asks).
        a._place(*other)
        b._place(*pose)
        assert a.touches(crept, b, other) == bool(crept_contacts)
        assert a.touches(pose, b, other) == bool(fast_contacts)
    assert touching > 30 and apart > 30 and touching - capped > 10  # every kind of answer was compared
