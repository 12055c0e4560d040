"""Issue 20: which PDOs carry the cyclic objects (drives.canopen.pdo_plan), over a drive's PDOs as
the inventory reads them: 8-byte frames within each mapping's entries, one object per PDO, the
drive's default mapping (a TPDO may carry more; an RPDO exactly the objects)."""

from __future__ import annotations

from drives.canopen.inventory import DrivePdo
from drives.canopen.pdo_plan import DEFAULT, ONE_PER_PDO, PACKED, decode_mapping, mapping_word, pack, plans
from drives.cia402 import (
    CONTROLWORD,
    MODES_OF_OPERATION,
    POSITION_ACTUAL,
    STATUSWORD,
    TARGET_TORQUE,
    VELOCITY_ACTUAL,
    ObjectSpec,
)

TPDO_WITH_POSITION = (STATUSWORD, VELOCITY_ACTUAL, POSITION_ACTUAL)  # 2 + 4 + 4 bytes
RPDO = (CONTROLWORD, TARGET_TORQUE)


def pdos(transmit: bool, capacities: list[int], mappings: list[tuple[ObjectSpec, ...]] | None = None) -> list[DrivePdo]:
    base = 0x1800 if transmit else 0x1400
    mappings = mappings or [()] * len(capacities)
    return [DrivePdo(n + 1, transmit, base + n, 0x80000000, False, False, capacity,
                     tuple(mapping_word(spec) for spec in mapping))
            for n, (capacity, mapping) in enumerate(zip(capacities, mappings))]


def layout(plan) -> list[tuple[str, tuple[int, ...]]]:
    return [(frame.pdo.label, tuple(spec.index for spec in frame.objects)) for frame in plan.frames]


def test_packed_frames_hold_at_most_8_bytes_and_the_entries_each_mapping_holds() -> None:
    # 10 bytes: two frames whatever the entries
    assert [[s.index for s in f] for _, f in pack(TPDO_WITH_POSITION, [8, 8])] == [[0x6041, 0x606C], [0x6064]]
    # the Technosoft IDM/ISCM's TPDO mappings hold 1, 2, 2, 2 entries (tests/data/eds)
    found, _ = plans(TPDO_WITH_POSITION, pdos(True, [1, 2, 2, 2]), exact=False)
    assert found[0].how == PACKED
    assert layout(found[0]) == [("TPDO1", (0x6041,)), ("TPDO2", (0x606C, 0x6064))]
    # a PDO whose mapping has no entries (0x1A01 with sub 0 only) is skipped
    found, _ = plans(TPDO_WITH_POSITION, pdos(True, [3, 0, 1]), exact=False)
    assert layout(found[0]) == [("TPDO1", (0x6041, 0x606C)), ("TPDO3", (0x6064,))]


def test_the_candidates_come_in_order_without_repeats() -> None:
    found, skipped = plans(TPDO_WITH_POSITION, pdos(True, [8, 8, 8, 8]), exact=False)
    assert [plan.how for plan in found] == [PACKED, ONE_PER_PDO]
    assert layout(found[1]) == [("TPDO1", (0x6041,)), ("TPDO2", (0x606C,)), ("TPDO3", (0x6064,))]
    assert skipped == [f"{DEFAULT}: no set of the drive's PDOs carries 0x6041, 0x606C, 0x6064"]
    # one object alone: "one per PDO" is the packed plan again, not tried twice
    found, _ = plans((STATUSWORD,), pdos(True, [8]), exact=False)
    assert [plan.how for plan in found] == [PACKED]


def test_too_few_pdos_say_why() -> None:
    found, skipped = plans(TPDO_WITH_POSITION, pdos(True, [1]), exact=False)
    assert found == []
    assert skipped[0] == f"{PACKED}: the drive's 1 PDOs of this direction hold 1 entries of at most 8 bytes"
    assert skipped[1] == f"{ONE_PER_PDO}: 3 objects, 1 PDOs that can map one"


def test_the_default_mapping_uses_the_fewest_pdos_and_may_carry_more_on_a_tpdo() -> None:
    # WITTENSTEIN simco's default TPDOs: [6041], [6041, 6064], [6041, 606C], [6041, 6077]
    torque_actual = ObjectSpec(0x6077, "Torque actual value", TARGET_TORQUE.data_type, "ro")
    defaults = [(STATUSWORD,), (STATUSWORD, POSITION_ACTUAL), (STATUSWORD, VELOCITY_ACTUAL), (STATUSWORD, torque_actual)]
    found, _ = plans((STATUSWORD, VELOCITY_ACTUAL), pdos(True, [8] * 4, defaults), exact=False)
    assert (found[-1].how, layout(found[-1])) == (DEFAULT, [("TPDO3", (0x6041, 0x606C))])
    assert not any(frame.remap for frame in found[-1].frames)
    found, _ = plans(TPDO_WITH_POSITION, pdos(True, [8] * 4, defaults), exact=False)
    assert layout(found[-1]) == [("TPDO2", (0x6041, 0x6064)), ("TPDO3", (0x6041, 0x606C))]


def test_an_rpdo_default_must_carry_exactly_controlword_and_torque() -> None:
    # WITTENSTEIN simco's default RPDOs: [6040], [6040, 607A, 3805], [6040, 60FF], [6040, 6071]
    target = ObjectSpec(0x607A, "Target position", POSITION_ACTUAL.data_type, "rw")
    velocity = ObjectSpec(0x60FF, "Target velocity", POSITION_ACTUAL.data_type, "rw")
    found, _ = plans(RPDO, pdos(False, [8] * 4, [(CONTROLWORD,), (CONTROLWORD, target), (CONTROLWORD, velocity), RPDO]),
                     exact=True)
    assert (found[-1].how, layout(found[-1])) == (DEFAULT, [("RPDO4", (0x6040, 0x6071))])
    # a default RPDO with a third object (the mode) is not used: the master would write it every cycle
    found, skipped = plans(RPDO, pdos(False, [0, 0], [(CONTROLWORD, TARGET_TORQUE, MODES_OF_OPERATION), ()]), exact=True)
    assert found == [] and skipped[-1] == f"{DEFAULT}: no set of the drive's PDOs carries exactly 0x6040, 0x6071"


def test_mapping_words_decode_with_the_objects_own_types() -> None:
    assert decode_mapping([0x60410010, 0x606C0020]) == (STATUSWORD, VELOCITY_ACTUAL)  # INTEGER32 velocity, signed
    (record_entry,) = decode_mapping([0x60C10120])  # an unknown object's sub-index, as an unsigned of its length
    assert (record_entry.index, record_entry.subindex, record_entry.data_type.size) == (0x60C1, 1, 4)
    assert decode_mapping([0x606C0010]) == ()  # a known object at another length: not decodable
    assert decode_mapping([0x60410010, 0x20000018]) == ()  # 24 bits
