"""The compiled drive loop: a two-wheel drivetrain's whole per-step path in C, n steps per call.

`fmus/common/drive_loop.c` runs the wheel-speed PI (or the servo setpoint), the unit conversions,
one step of both wheel FMUs through the shim's slots and the planar chassis with its load torques,
with everything in one C structure. `DriveLoop` fills that structure (fields by name, see the C
source for their meaning and units) and runs it. The physics and its Python reference live in
`twin.robot`; this module only knows the structure, so the layering holds.

The loop knows nothing of the world: `run` takes a travel budget (how far the robot may move with
no contact possible) and stops before the chassis update of a step that would use it up, leaving
that update and its contact checks to the caller.
"""

from __future__ import annotations

import ctypes
import functools
import struct
from collections.abc import Iterable, Sequence

from twin.core.errors import FmuError
from twin.cosim.step_group import StepGroup

__all__ = ["DriveLoop"]

_D = ctypes.c_double


class _DriveState(ctypes.Structure):
    """`TwinDrive` in fmus/common/drive_loop.c (same fields, same order)."""

    _fields_ = (
        ("slots", ctypes.c_void_p),
        ("step_index", ctypes.c_void_p),
        ("slip_regions", ctypes.c_void_p),
        ("n_slip_regions", ctypes.c_int),
        ("servo", ctypes.c_int),
        ("has_slip", ctypes.c_int),
        ("failed", ctypes.c_int),
        ("stopped_on_budget", ctypes.c_int),
        *(
            (name, _D)
            for name in (
                "budget_m",
                "step_s",
                "kp",
                "ki",
                "v_max",
                "cmd_scale",
                "cmd_offset",
                "load_scale",
                "load_offset",
                "speed_scale",
                "speed_offset",
                "half_r",
                "r_over_b",
                "m_common",
                "m_diff",
                "j",
                "j_over_h",
                "k_common",
                "k_diff",
                "roll_nm",
                "roll_gain",
                "hold_damping",
                "slip",
                "reach_m",
                "ramp_radps",
                "target_left",
                "target_right",
                "ref_left",
                "ref_right",
                "w_left",
                "w_right",
                "int_left",
                "int_right",
                "volt_left",
                "volt_right",
                "x_m",
                "y_m",
                "yaw_rad",
                "v_mps",
                "yaw_rate_radps",
                "ax_mps2",
                "ay_mps2",
                "yaw_accel_radps2",
                "block_common",
                "block_diff",
                "w_left_prev_radps",
                "w_right_prev_radps",
                "wheel_angle_left_rad",
                "wheel_angle_right_rad",
                "load_left_nm",
                "load_right_nm",
            )
        ),
        ("blocked", ctypes.c_bool),
    )


_KINDS = {field[0]: field[1] for field in _DriveState._fields_}  # each field's ctypes type

# Fields set through `write`: numbers and flags, not the pointers or the run's outputs.
_WRITABLE = frozenset(field[0] for field in _DriveState._fields_) - {
    "slots",
    "step_index",
    "slip_regions",
    "n_slip_regions",
    "has_slip",
    "failed",
    "stopped_on_budget",
    "budget_m",
}
MAX_RUN = 1 << 30  # steps per C call (its count is an int)


class DriveLoop:
    """The compiled per-step loop over a group of two FMU instances (left, right) stepped by the shim.

    `state` is the C structure itself: read its fields directly where speed matters. Between calls
    to `run` the structure holds the whole state of the drive (wheels and chassis).
    """

    def __init__(self, group: StepGroup, *, slip_regions: Iterable[Sequence[float]] | None) -> None:
        """Bind the loop to `group`'s slots and step counter; every number starts at zero.

        Args:
            group: The two wheel instances, left then right, stepped by the compiled shim.
            slip_regions: None for no slip; else rectangles `(x_min_m, x_max_m, y_min_m, y_max_m,
                slip)`, the first containing the robot wins, and the field `slip` applies outside.

        Raises:
            FmuError: If the group is not stepped by the shim or does not hold two instances.
        """
        shim = group.shim()
        if shim is None or group.size != 2:
            msg = "the compiled drive loop needs two FMU instances stepped by the compiled shim"
            raise FmuError(msg)
        library, slots, index = shim
        self._group = group
        self._keep = (slots, index)
        regions = [tuple(float(v) for v in region) for region in slip_regions or ()]
        if any(len(region) != 5 for region in regions):
            msg = "slip regions are (x_min_m, x_max_m, y_min_m, y_max_m, slip)"
            raise ValueError(msg)
        self._regions = (_D * max(1, 5 * len(regions)))(*(v for region in regions for v in region))
        state = _DriveState()
        state.slots = ctypes.addressof(slots)
        state.step_index = ctypes.addressof(index)
        state.slip_regions = ctypes.addressof(self._regions)
        state.n_slip_regions = len(regions)
        state.has_slip = int(slip_regions is not None)
        state.failed = -1
        self.state = state
        function = library.twin_drive_run
        function.restype = ctypes.c_int  # no argtypes: a pointer and a small int pass as they are
        self._run = functools.partial(function, ctypes.byref(state))
        #: `run` without its checks, for a caller that inlines them: `step(count)` with `count` at most
        #: `MAX_RUN` and `state.budget_m` set before; the caller checks `state.failed` itself.
        self.step = self._run
        # The structure's bytes, for readers that take several fields in one `struct` call.
        self.buffer = memoryview((ctypes.c_ubyte * ctypes.sizeof(state)).from_buffer(state))

    def write(self, **values: float) -> None:
        """Set fields by name (numbers; `servo` and `blocked` as flags).

        Raises:
            ValueError: If a name is not a settable field.
        """
        unknown = sorted(set(values) - _WRITABLE)
        if unknown:
            msg = f"drive loop: no field(s) {', '.join(unknown)}"
            raise ValueError(msg)
        state = self.state
        for name, value in values.items():
            setattr(state, name, value)

    def raise_failure(self) -> None:
        """Raise the FmuError of the instance whose failure `step` left in `state.failed`."""
        self._group.raise_failure(self.state.failed)

    @staticmethod
    def offset(name: str) -> int:
        """Byte offset of field `name` in `buffer` (fields are doubles but for the flags and pointers)."""
        offset: int = getattr(_DriveState, name).offset
        return offset

    @staticmethod
    def span(names: Sequence[str]) -> struct.Struct:
        """A `struct` packing these fields of `buffer` at once, from the first one's offset.

        The fields must follow each other in the structure (doubles, or a flag as a bool), so a
        caller hands over or takes back many of them in one call instead of one attribute each.

        Raises:
            ValueError: If the fields do not follow each other without a gap.
        """
        codes = {_D: "d", ctypes.c_bool: "?"}
        fmt = "<"
        end = getattr(_DriveState, names[0]).offset
        for name in names:
            field = getattr(_DriveState, name)
            kind = _KINDS[name]
            if field.offset != end or kind not in codes:
                msg = f"drive loop: field {name} does not follow the one before it"
                raise ValueError(msg)
            fmt += codes[kind]
            end = field.offset + field.size
        return struct.Struct(fmt)

    def read(self, names: Iterable[str]) -> tuple[float, ...]:
        """The fields `names`, in that order."""
        state = self.state
        return tuple(getattr(state, name) for name in names)

    def run(self, count: int, budget_m: float) -> int:
        """Run up to `count` communication steps with `budget_m` of contact-free motion (math.inf: no world).

        Returns the steps fully taken. When `state.stopped_on_budget` is set after it, the budget ran
        out: the FMUs of the next step have been stepped and `w_left`, `w_right` hold their speeds,
        and the caller must do that step's chassis update (with its contact checks) before anything
        else.

        Raises:
            FmuError: If an FMU fails; names the FMU, instance, sim time, function and status.
        """
        state = self.state
        state.budget_m = budget_m
        done: int = self._run(count if count < MAX_RUN else MAX_RUN)
        if done < count and state.failed >= 0:
            self._group.raise_failure(state.failed)
        return done
