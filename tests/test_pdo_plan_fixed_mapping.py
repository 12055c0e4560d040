"""break15: a drive whose RPDO1 mapping is fixed (read-only) and already carries exactly 0x6040 + 0x6071.

docs/foreign-drive.md: "If the drive refuses (..., or a read-only mapping), the next plan: one object
per PDO, then the drive's default mapping where it carries what is needed".  `plans` drops the default
plan when the packed plan has the same shape (`_add` compares PDO numbers and objects, not `remap`), so
the plan that writes nothing is never tried: `haptic-bus sim --eds E` with E = wittenstein_simco.eds whose
0x1600 subs are AccessType=ro with 0x1600 = (0x60400010, 0x60710010), then `haptic-bus run cia402-handle`
against it: "drive error: ... no PDO mapping the drive accepts: packed: RPDO1 (0x6040, 0x6071) refused
(SDO abort writing 0x1600:00 ...: 0x06010002 Attempt to write a read only object); one object per PDO:
RPDO1 (0x6040), RPDO2 (0x6071) refused (...)", exit 1.
"""

from __future__ import annotations

from drives.canopen.inventory import DrivePdo
from drives.canopen.pdo_plan import DEFAULT, plans
from drives.cia402 import CONTROLWORD, TARGET_TORQUE


def test_a_fixed_rpdo_mapping_that_carries_exactly_the_objects_is_tried_as_it_stands() -> None:
    fixed = DrivePdo(number=1, transmit=False, communication=0x1400, cob_word=0x205, has_inhibit_time=False,
                     has_event_timer=False, capacity=2, mapping=(0x60400010, 0x60710010))
    found, _ = plans([CONTROLWORD, TARGET_TORQUE], [fixed], exact=True)
    as_they_stand = [plan for plan in found if all(not frame.remap for frame in plan.frames)]
    assert [plan.how for plan in as_they_stand] == [DEFAULT]
    assert found[-1].how == DEFAULT  # tried after the plans that write the mapping were refused
