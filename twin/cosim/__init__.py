"""FMU co-simulation: build, load, bind to the drive contract, and step FMUs fast.

The project's FMUs are built from `fmus/`; any FMI 2.0/3.0 Co-Simulation FMU loads. The only package
that imports fmpy.
"""

import twin.cosim._fmpy_import  # noqa: F401  (first: fmpy imported without its `ldconfig -p` run)
from twin.cosim.adapter import Stepper
from twin.cosim.build import build_all, build_fmu, resolve_fmu
from twin.cosim.contract import Binding, FmuMapping, Profile, RoleBinding, RoleMap, bind, check_contract, load_mapping
from twin.cosim.description import FmuInfo, read_fmu_info
from twin.cosim.fmu import FmuFile

__all__ = [
    "Binding",
    "FmuFile",
    "FmuInfo",
    "FmuMapping",
    "Profile",
    "RoleBinding",
    "RoleMap",
    "Stepper",
    "bind",
    "build_all",
    "build_fmu",
    "check_contract",
    "load_mapping",
    "read_fmu_info",
    "resolve_fmu",
]
