"""Where the test suite's own FMU sources are, and a builder for them."""

from __future__ import annotations

from pathlib import Path

from twin.cosim.build import FMUS_DIR, FmiVersion, build_fmu

ACME_DIR = Path(__file__).resolve().parent / "fmus" / "acme_drive"
FAULTY_DIR = FMUS_DIR / "testing" / "faulty_motor"
# fault_mode values of the faulty motor (fmus/testing/faulty_motor/faulty_motor.c).
FAULTS = {"none": 0, "segfault": 1, "abort": 2, "hang": 3, "nan": 4}


def acme(variant: str = "acme_drive", fmi_version: FmiVersion = 2) -> Path:
    """Build (or reuse) the stand-in vendor FMU."""
    return build_fmu(ACME_DIR, variant, fmi_version=fmi_version).path


def faulty(variant: str = "faulty_motor_servo", fmi_version: FmiVersion = 2) -> Path:
    """Build (or reuse) the project's motor with a fault injected (mapping parameters fault_mode, fault_time)."""
    return build_fmu(FAULTY_DIR, variant, fmi_version=fmi_version).path


ME_DIR = FMUS_DIR / "testing" / "dc_motor_me"


def model_exchange(variant: str = "xm430_w210_servo_me", fmi_version: FmiVersion = 2) -> Path:
    """Build (or reuse) the project's motor as a Model Exchange FMU."""
    return build_fmu(ME_DIR, variant, fmi_version=fmi_version).path
