"""The compiled drive loop (`api: native`) against the Python reference (`api: lowlevel`): the same
trajectory and wheel signals for both profiles, with slip, through vendor units, and through wall
contacts, where the compiled loop hands the steps near the world to the Python path."""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from tests.unit.cosim.helpers import acme
from tests.unit.robot.test_drivetrain import ACME_MOTOR
from twin.core.errors import FmuError
from twin.cosim.drive_loop import DriveLoop
from twin.robot.chassis import ChassisDynamics, ChassisParams, SlipModel, SlipRegion
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import _WHEEL_STATE, FmuDrivetrain
from twin.sim.scenario import default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.world import build_scene, load_robot, load_world
from twin.world.scene import CollisionMonitor

REPO = Path(__file__).resolve().parents[3]
MS = 1_000_000
WAFFLE = ChassisParams.tb3_waffle()
BATCHES = (5, 1, 7, 3, 5, 30)  # the loop advances by uneven batches between its events
# Accelerate, turn, reverse, stop: (v m/s, w rad/s, steps).
SCRIPT = ((0.2, 0.0, 300), (0.15, 1.2, 400), (-0.1, -0.6, 300), (0.0, 0.0, 200), (0.26, -1.8, 300))
TOL = 1e-12

Trace = list[tuple[float | bool, ...]]


def _drive_script(dt: FmuDrivetrain, script: Sequence[tuple[float, float, int]]) -> Trace:
    trace: Trace = []
    k = 0
    for v, w, steps in script:
        dt.set_cmd_vel(v, w)
        left = steps
        while left > 0:
            n = min(left, BATCHES[k % len(BATCHES)])
            dt.advance(n)
            left -= n
            k += 1
            wheels = dt.wheel_state()
            trace.append((dt.t_ns, *dt.chassis_state(), *(x for pair in wheels for x in pair)))
    return trace


def _run(
    drive: FmuDrive,
    script: Sequence[tuple[float, float, int]] = SCRIPT,
    *,
    params: ChassisParams = WAFFLE,
    contact: Callable[[float, float, float], bool] | None = None,
    free: Callable[[float, float, float], float] | None = None,
    radius_m: float = 0.0,
) -> Trace:
    with FmuDrivetrain(
        drive, params, step_ns=MS, contact=contact, free_distance=free, bounding_radius_m=radius_m
    ) as dt:
        assert dt.native == (drive.api == "native")
        return _drive_script(dt, script)


def _both(drive: FmuDrive, **kwargs: object) -> tuple[Trace, Trace]:
    native = _run(drive, **kwargs)  # type: ignore[arg-type]
    python = _run(FmuDrive(**{**_fields(drive), "api": "lowlevel"}), **kwargs)  # type: ignore[arg-type]
    return native, python


def _fields(drive: FmuDrive) -> dict[str, object]:
    return {name: getattr(drive, name) for name in FmuDrive.__dataclass_fields__}


def assert_same(native: Trace, python: Trace) -> None:
    assert len(native) == len(python)
    for k, (a, b) in enumerate(zip(native, python, strict=True)):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if isinstance(x, int):  # the time, and `blocked`
                assert x == y, f"record {k}, field {i}: {x} != {y}"
            elif not (math.isnan(x) and math.isnan(y)):
                assert abs(x - y) <= TOL * max(1.0, abs(y)), f"record {k}, field {i}: {x!r} != {y!r}"


class Counted:
    """A contact callable that counts its calls and the contacts it reported."""

    def __init__(self, contact: Callable[[float, float, float], bool]) -> None:
        self.contact = contact
        self.calls = self.hits = 0

    def __call__(self, x_m: float, y_m: float, yaw_rad: float) -> bool:
        self.calls += 1
        hit = self.contact(x_m, y_m, yaw_rad)
        self.hits += hit
        return hit


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("profile,fmu", [("voltage", "xm430_w210"), ("velocity-servo", "xm430_w210_servo")])
def test_native_loop_gives_the_python_trajectory_and_wheel_signals(profile: str, fmu: str, fmi_version: int) -> None:
    drive = FmuDrive(fmu=f"builtin:{fmu}", profile=profile, fmi_version=fmi_version)  # type: ignore[arg-type]
    native, python = _both(drive)
    assert_same(native, python)
    assert python[-1][1] != 0.0 and python[-1][3] != 0.0  # it went somewhere and turned


@pytest.mark.parametrize("profile,fmu", [("voltage", "xl430_w250"), ("velocity-servo", "xl430_w250_servo")])
def test_native_loop_matches_with_slip_regions(profile: str, fmu: str) -> None:
    slip = SlipModel(
        slip=0.05,
        regions=(
            SlipRegion(x_min_m=0.02, x_max_m=0.08, y_min_m=-1.0, y_max_m=1.0, slip=0.6),
            SlipRegion(x_min_m=-1.0, x_max_m=1.0, y_min_m=0.03, y_max_m=1.0, slip=0.3),
        ),
    )
    drive = FmuDrive(fmu=f"builtin:{fmu}", profile=profile, slip=slip)  # type: ignore[arg-type]
    native, python = _both(drive, params=ChassisParams.tb3_burger())
    assert_same(native, python)
    no_slip, _ = _both(FmuDrive(fmu=f"builtin:{fmu}", profile=profile), params=ChassisParams.tb3_burger())  # type: ignore[arg-type]
    assert abs(native[-1][1] - no_slip[-1][1]) > 1e-3  # the slip changed the run


def test_native_loop_converts_vendor_units_as_the_python_path() -> None:
    drive = FmuDrive(
        fmu_file=acme(),
        mapping=REPO / "fmus" / "maps" / "acme_drive.yaml",
        motor=ACME_MOTOR,
    )
    native, python = _both(drive)
    assert_same(native, python)


@pytest.mark.parametrize("profile,fmu", [("voltage", "xm430_w210"), ("velocity-servo", "xm430_w210_servo")])
def test_native_loop_matches_through_a_wall_stall_and_release(profile: str, fmu: str) -> None:
    # The chassis stall scenario: a wall at x = 0.1, driven into, stalled against, then backed off.
    script = ((0.2, 0.0, 400), (0.2, 0.0, 500), (-0.1, 0.0, 500))
    drive = FmuDrive(fmu=f"builtin:{fmu}", profile=profile)  # type: ignore[arg-type]
    runs = {}
    for api in ("native", "lowlevel"):
        contact = Counted(lambda x, y, yaw: x > 0.1)
        trace = _run(
            FmuDrive(**{**_fields(drive), "api": api}),  # type: ignore[arg-type]
            script,
            contact=contact,
            free=lambda x, y, yaw: max(0.0, 0.1 - x),
        )
        runs[api] = (trace, contact.calls)
    (native, native_calls), (python, python_calls) = runs["native"], runs["lowlevel"]
    assert_same(native, python)
    blocked = [record[9] for record in python]
    assert any(blocked) and not blocked[-1]  # it stalled at the wall, and backing off freed it
    assert max(record[1] for record in python) <= 0.1
    # The compiled loop checked contact only near the wall, the Python path every moving step.
    assert 0 < native_calls < python_calls / 5


def test_native_loop_counts_rotation_in_its_travel_bound() -> None:
    # A wall at x = 0.3 touched by a point 0.2 m ahead of the base: turning alone moves it, so the
    # compiled loop must count |rotation| x 0.2 m against the free distance.
    reach = 0.2

    def front_x(x: float, yaw: float) -> float:
        return x + reach * math.cos(yaw)

    script = ((0.0, 1.5, 600), (0.15, -1.0, 900), (0.0, 1.5, 700), (-0.1, 0.0, 300))
    runs = []
    for api in ("native", "lowlevel"):
        contact = Counted(lambda x, y, yaw: front_x(x, yaw) > 0.3)
        trace = _run(
            FmuDrive(api=api),  # type: ignore[arg-type]
            script,
            contact=contact,
            free=lambda x, y, yaw: max(0.0, 0.3 - front_x(x, yaw)),
            radius_m=reach,
        )
        runs.append((trace, contact.calls))
    (native, native_calls), (python, python_calls) = runs
    assert_same(native, python)
    assert any(record[9] for record in python)  # the wall was reached
    assert native_calls < python_calls


def test_native_loop_matches_in_the_house_with_the_collision_monitor() -> None:
    # The default scenario's world and robot, driven into the wall south of the start and turned away.
    scenario = load_scenario(default_scenario_path())
    world = load_world(scenario.world.sdf, model_path=scenario.world.model_path)
    robot = load_robot(scenario.robot.model, model_path=scenario.world.model_path)
    scene = build_scene(world, exclude_models=(robot.name,))
    body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
    script = ((0.2, 0.0, 8000), (-0.05, 0.8, 1500), (0.2, 0.0, 1500))
    runs = []
    for api in ("native", "lowlevel"):
        monitor = CollisionMonitor(scene, body)
        contact = Counted(lambda x, y, yaw, monitor=monitor: bool(monitor.check(x, y, yaw)))
        with FmuDrivetrain(
            FmuDrive(api=api),  # type: ignore[arg-type]
            WAFFLE,
            step_ns=MS,
            pose=(0.0, 0.0, -math.pi / 2),
            contact=contact,
            free_distance=monitor.free_m,
            bounding_radius_m=body.radius_m,
        ) as dt:
            runs.append((_drive_script(dt, script), contact))
    (native, native_contact), (python, python_contact) = runs
    assert_same(native, python)
    assert native_contact.hits > 0 and python_contact.hits > 0
    assert native_contact.calls < python_contact.calls / 2  # at the wall, turning away, it checks each step
    assert -1.281 < min(record[2] for record in python) < -0.9  # stopped at the wall's face


def test_native_api_falls_back_to_python_when_the_shim_cannot_be_built(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    import twin.cosim.build

    def no_compiler() -> Path:
        raise FmuError("cannot build the step shim: no C compiler")

    monkeypatch.setattr(twin.cosim.build, "build_shim", no_compiler)
    with caplog.at_level(logging.WARNING), FmuDrivetrain(FmuDrive(), WAFFLE, step_ns=MS) as dt:
        assert not dt.native
        trace = _drive_script(dt, SCRIPT[:2])
    assert "no C compiler" in caplog.text
    monkeypatch.undo()
    assert_same(trace, _run(FmuDrive(), SCRIPT[:2]))


@pytest.mark.parametrize("profile,fmu", [("voltage", "xm430_w210"), ("velocity-servo", "xm430_w210_servo")])
def test_native_readers_return_what_the_loop_structure_holds(profile: str, fmu: str) -> None:
    # With the compiled loop, chassis_state and wheel_state read the loop's structure and the FMUs'
    # outputs several fields at a time; the methods of the class read them one by one.
    drive = FmuDrive(fmu=f"builtin:{fmu}", profile=profile)  # type: ignore[arg-type]
    with FmuDrivetrain(drive, WAFFLE, step_ns=MS, contact=None, free_distance=None, bounding_radius_m=0.0) as dt:
        assert dt.native
        for v, w, steps in SCRIPT:
            dt.set_cmd_vel(v, w)
            dt.advance(steps)
            assert dt.chassis_state() == FmuDrivetrain.chassis_state(dt)
            assert dt.pose() == FmuDrivetrain.pose(dt) == dt.chassis_state()[:3]  # what a fleet reads
            assert repr(dt.wheel_state()) == repr(FmuDrivetrain.wheel_state(dt))  # repr: NaN where there is none
        assert dt.chassis_state().x_m != 0.0
    python = FmuDrive(fmu=f"builtin:{fmu}", profile=profile, api="lowlevel")  # type: ignore[arg-type]
    with FmuDrivetrain(python, WAFFLE, step_ns=MS, contact=None, free_distance=None, bounding_radius_m=0.0) as dt:
        assert not dt.native
        dt.set_cmd_vel(*SCRIPT[1][:2])
        dt.advance(SCRIPT[1][2])
        assert dt.pose() == dt.chassis_state()[:3] != (0.0, 0.0, 0.0)


@pytest.mark.parametrize("profile,fmu", [("voltage", "xm430_w210"), ("velocity-servo", "xm430_w210_servo")])
def test_a_drive_creeping_in_place_against_a_wall_stays_in_the_compiled_loop(profile: str, fmu: str) -> None:
    # Driven into a wall at x = 1.05 with a turn far below the yaw's float resolution: the wall blocks
    # the forward motion and the turn goes on at ~1e-14 rad/s, leaving the pose where it is, step
    # after step. Such a step moves nothing, so neither path checks it or refuses it: the compiled
    # loop takes them all, along the Python path's trajectory.
    script = ((0.15, 1e-14, 600), (0.15, 1e-14, 1500), (-0.1, 0.0, 300))
    drive = FmuDrive(fmu=f"builtin:{fmu}", profile=profile)  # type: ignore[arg-type]
    runs = {}
    for api in ("native", "lowlevel"):
        contact = Counted(lambda x, y, yaw: x > 1.05)
        with FmuDrivetrain(
            FmuDrive(**{**_fields(drive), "api": api}),  # type: ignore[arg-type]
            WAFFLE,
            step_ns=MS,
            pose=(1.0, 2.0, 0.3),
            contact=contact,
            free_distance=lambda x, y, yaw: max(0.0, 1.05 - 1e-3 - x),  # none left within 1 mm of the wall
            probe=lambda x, y, yaw: x > 1.05,  # (the blocked drive's probe at each advance, not counted)
            bounding_radius_m=0.2,
        ) as dt:
            runs[api] = (_drive_script(dt, script), contact.calls)
    (native, native_calls), (python, python_calls) = runs.values()
    assert_same(native, python)
    blocked = [record[9] for record in python]
    assert sum(blocked) > 100 and not blocked[-1]  # pressed against the wall, then backed off
    creeping = [now for before, now in itertools.pairwise(python) if now[9] and now[5] and now[1:4] == before[1:4]]
    assert len(creeping) > 100  # turning (yaw rate not 0) with the pose unchanged
    # The compiled loop checks near the wall only (the Python path at every moving step), and none of
    # the creeping steps: the approach and the backing off, of 2400 steps.
    assert native_calls < 100 < python_calls


class MovingFace:
    """A face at `x = at` that the robot's flat front (0.2 m ahead, 0.3 m wide) must not cross, moved
    as another robot moves between the drive's advances."""

    def __init__(self, at: float) -> None:
        self.at = at
        self.calls = 0

    def front(self, x_m: float, yaw_rad: float) -> float:
        """The front's farthest x: turning either way brings a corner forward."""
        return x_m + 0.2 * math.cos(yaw_rad) + 0.15 * abs(math.sin(yaw_rad))

    def __call__(self, x_m: float, y_m: float, yaw_rad: float) -> bool:
        self.calls += 1
        return self.front(x_m, yaw_rad) > self.at

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        return max(0.0, self.at - 1e-3 - self.front(x_m, yaw_rad))


@pytest.mark.parametrize("api", ["native", "lowlevel"])
def test_a_stopped_robot_something_moved_into_backs_off_once_it_has_gone(api: str) -> None:
    # Driven, turned and stopped: its wheels slow towards zero for ever (each step's motion below the
    # pose's resolution, its sign noise). Then a face is moved into its front, as another robot comes
    # into one that stands, and later away. Those steps move nothing, so nothing refuses them: no
    # check, and no block in the direction of the noise, which would hold the robot against its
    # next command (it did, for ever: a 1e-18 m/s backwards step refused set "blocked backwards").
    phases = (
        (1.5, 0.15, 0.0, 500),
        (1.5, 0.0, 0.3, 600),
        (1.5, 0.0, 0.0, 1500),
        (1.26, 0.0, 0.0, 2500),
        (1.5, -0.1, 0.0, 600),
    )
    face = MovingFace(phases[0][0])
    with FmuDrivetrain(
        FmuDrive(fmu="builtin:xm430_w210_servo", profile="velocity-servo", api=api),
        WAFFLE,
        step_ns=MS,
        pose=(1.0, 2.0, 0.0),
        contact=face,
        free_distance=face.free_m,
        bounding_radius_m=0.25,
    ) as dt:
        calls = []
        for at, v, w, steps in phases:
            face.at = at
            dt.set_cmd_vel(v, w)
            dt.advance(steps)
            calls.append(face.calls)
            if at == 1.26:
                stopped = dt.chassis_state()
                assert face.front(stopped.x_m, stopped.yaw_rad) > 1.26 and not stopped.blocked  # the face in it
        end = dt.chassis_state()
    assert calls[3] == calls[2]  # 2500 steps standing in contact, none checked
    assert end.x_m < stopped.x_m - 0.03 and not end.blocked  # backed off


def test_the_state_handed_to_the_compiled_loop_and_back_is_every_field_by_name() -> None:
    # `_to_native` and `_to_python` move the wheels' and the chassis' state with one `struct` call
    # over consecutive fields of the loop's structure; the fields by name must hold the same numbers.
    drive = FmuDrive(fmu="builtin:xm430_w210", profile="voltage")
    with FmuDrivetrain(drive, WAFFLE, step_ns=MS, contact=None, free_distance=None, bounding_radius_m=0.0) as dt:
        assert dt.native and dt._loop is not None
        dt.set_cmd_vel(0.2, 0.7)
        dt.advance(250)
        dt._to_python()
        wheels = tuple(getattr(dt, f"_{name}") for name in _WHEEL_STATE)
        assert wheels == dt._loop.read(_WHEEL_STATE)
        assert dt._chassis.dynamics() == ChassisDynamics._make(dt._loop.read(ChassisDynamics._fields))
        dt._chassis.x_m += 1.0  # a change on the Python side reaches the loop
        dt._to_native()
        assert dt._loop.read(("x_m",))[0] == dt._chassis.x_m
    with pytest.raises(ValueError, match="yaw_rad does not follow"):
        DriveLoop.span(("x_m", "yaw_rad"))


def test_a_robot_pushing_against_another_follows_it_when_it_drives_off() -> None:
    # Pushing forward against a face (another robot) and turning left until a second obstacle stops
    # the turn (at yaw 0.05): both modes blocked. The obstacles move off between advances; the
    # blocks lift at the next advance (each blocked mode probed 2 mm on), and the robot goes on as
    # commanded, on both paths alike. Before, a block held as long as the drive pushed, whatever
    # had gone: a robot blocked turning left stayed so for the rest of a two-robot run while its
    # controller asked for a left turn.
    runs = {}
    for api in ("native", "lowlevel"):
        front = MovingFace(1.3)
        turn_stop = {"yaw": 0.05}

        def touches(
            x: float, y: float, yaw: float, front: MovingFace = front, stop: dict[str, float] = turn_stop
        ) -> bool:
            return front(x, y, yaw) or yaw > stop["yaw"]

        with FmuDrivetrain(
            FmuDrive(fmu="builtin:xm430_w210_servo", profile="velocity-servo", api=api),  # type: ignore[arg-type]
            WAFFLE,
            step_ns=MS,
            pose=(1.0, 2.0, 0.0),
            contact=touches,
            free_distance=lambda x, y, yaw: 0.0,  # every moving step checked, on both paths
            bounding_radius_m=0.25,
        ) as dt:
            trace: Trace = []
            dt.set_cmd_vel(0.15, 0.5)
            for front_at, stop_yaw, steps in ((1.3, 0.05, 1500), (1.6, 0.05, 400), (1.6, 9.0, 600)):
                front.at, turn_stop["yaw"] = front_at, stop_yaw
                for _ in range(steps // 5):
                    dt.advance(5)
                trace.append((dt.t_ns, *dt.chassis_state()))
            runs[api] = trace
    assert_same(runs["native"], runs["lowlevel"])
    pressed, followed, turned = runs["lowlevel"]
    assert pressed[9] and MovingFace(1.3).front(pressed[1], pressed[3]) > 1.29 and 0.04 < pressed[3] <= 0.05
    assert followed[1] > pressed[1] + 0.03 and followed[3] <= 0.05  # the face went: it drove on, not turning
    assert turned[3] > 0.1  # the turn's obstacle went too: it turned left
