"""Where the test suite's own FMU sources are, and a builder for them."""

from __future__ import annotations

from pathlib import Path

from twin.cosim.build import FmiVersion, build_fmu

ACME_DIR = Path(__file__).resolve().parent / "fmus" / "acme_drive"


def acme(variant: str = "acme_drive", fmi_version: FmiVersion = 2) -> Path:
    """Build (or reuse) the stand-in vendor FMU."""
    return build_fmu(ACME_DIR, variant, fmi_version=fmi_version).path
