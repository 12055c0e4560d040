"""Where the simulated drive's EDS (electronic data sheet) is shipped.

``haptic_sim_drive.eds`` describes the CANopen object dictionary of
:class:`sim_drive.canopen.slave.CanopenSimDrive`: communication objects (0x1000-0x1A03),
the CiA-402 objects it implements, and the manufacturer area (REAL64 values in SI units):

========  ===  =========================================================
index     sub  meaning
========  ===  =========================================================
0x2000    1-3  plant: m (kg), b (N s/m), sub-steps per SYNC (UNSIGNED16)
0x2001    1-3  scaling: velocity per count (m/s), position per count (m),
               force per torque (N per N m)
0x2002    1-5  timing (UNSIGNED8: 0 cia402, 1 ideal), SYNC count, virtual
               time (s), late RPDO count, RPDO length error count (ro)
0x2003    1-2  operator energy, wall energy (J, ro)
0x2010    1-7  operator model code (see ``sim_drive.operator.OPERATOR_CODES``)
               and its parameters p1..p6 (written before the code)
========  ===  =========================================================

With ``od="standard"`` (``haptic-bus sim --od standard``) the slave serves this EDS without the
manufacturer area, and states its scaling in the CiA-402 factor group instead (0x608F, 0x6090,
0x6091, 0x6092, 0x60A8, 0x60A9, read-only; see :mod:`sim_drive.canopen.standard_od`).
"""

from __future__ import annotations

import pathlib

EDS_NAME = "haptic_sim_drive.eds"
OD_KINDS = ("haptic", "standard")  # the slave's object dictionaries: the shipped EDS, or standard objects only


def eds_path() -> pathlib.Path:
    """The absolute path of the shipped EDS file."""
    return pathlib.Path(__file__).resolve().with_name(EDS_NAME)
