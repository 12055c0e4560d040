"""The shipped EDS: loads in canopen, has the objects the drive serves, with the right flags."""

from __future__ import annotations

import canopen
import pytest
from canopen.objectdictionary import ODRecord, ODVariable, datatypes, import_od

from drives.cia402 import OBJECTS
from sim_drive.device import SimulatedDrive
from sim_drive.eds import eds_path

NODE = 9


@pytest.fixture(scope="module")
def od() -> canopen.ObjectDictionary:
    return import_od(str(eds_path()), NODE)


def test_path_is_shipped_next_to_the_package() -> None:
    path = eds_path()
    assert path.is_file() and path.name == "haptic_sim_drive.eds" and path.parent.name == "sim_drive"


def test_communication_objects(od: canopen.ObjectDictionary) -> None:
    assert od[0x1000].default == 0x00020192
    assert od[0x1008].default == "haptic_bus simulated drive"
    assert od[0x1005].default == 0x80 and od[0x1006].default == 1000 and od[0x1007].default == 0
    assert od[0x1014].default == 0x80 + NODE
    assert od[0x1017].data_type == datatypes.UNSIGNED16
    assert isinstance(od[0x1016], canopen.objectdictionary.ODArray) and od[0x1016][1].writable
    assert [od[0x1018][s].data_type for s in range(1, 5)] == [datatypes.UNSIGNED32] * 4
    for base, cob in ((0x1400, 0x200), (0x1800, 0x180)):
        for n in range(4):
            com = od[base + n]
            default = com[1].default
            assert default & 0x7FF == cob + 0x100 * n + NODE
            assert bool(default >> 31) == (n > 0)  # only PDO 1 valid by default
            mapping = od[base + 0x200 + n]
            assert mapping[0].writable and all(mapping[k].writable for k in range(1, 9))


def test_cia402_objects_match_the_protocol_tables(od: canopen.ObjectDictionary) -> None:
    drive = SimulatedDrive()
    for index, spec in OBJECTS.items():
        var = od[index]
        assert isinstance(var, ODVariable), hex(index)
        assert var.data_type == spec.data_type.code, hex(index)
        assert var.writable == (spec.access == "rw"), hex(index)
        assert index in drive.readable_objects()
        assert var.writable == (index in drive.writable_objects()), hex(index)
    mappable = {i for i in OBJECTS if od[i].pdo_mappable}
    assert mappable == {0x603F, 0x6040, 0x6041, 0x6060, 0x6061, 0x6064, 0x606C, 0x6071, 0x6072, 0x6077}
    assert od[0x6502].default == 1 << 9 and od[0x6072].default == 3000 and od[0x6076].default == 200


def test_the_safety_chain_objects_are_in_the_eds(od: canopen.ObjectDictionary) -> None:
    """Issue 10: the heartbeat consumer, the RPDO deadline, 0x6007 and the error objects, with
    the power-on values the drive starts from (watchdogs off until a master sets them, 0x6007 fault)."""
    assert od[0x1001].data_type == datatypes.UNSIGNED8 and not od[0x1001].writable
    assert od[0x1016][1].data_type == datatypes.UNSIGNED32 and od[0x1016][1].default == 0
    assert od[0x1017].default == 100
    for n in range(4):
        deadline = od[0x1400 + n][5]
        assert deadline.data_type == datatypes.UNSIGNED16 and deadline.writable and deadline.default == 0
    option = od[0x6007]
    assert option.data_type == datatypes.INTEGER16 and option.writable and option.default == 1
    assert od[0x603F].data_type == datatypes.UNSIGNED16 and od[0x603F].pdo_mappable
    assert od[0x1014].default == 0x80 + NODE


def test_manufacturer_area_is_real64(od: canopen.ObjectDictionary) -> None:
    assert isinstance(od[0x2000], ODRecord)
    assert (od[0x2000][1].default, od[0x2000][2].default) == (0.5, 0.1)
    assert od[0x2001][1].data_type == datatypes.REAL64
    assert od[0x2010][1].data_type == datatypes.UNSIGNED8
    assert all(od[0x2010][k].data_type == datatypes.REAL64 for k in range(2, 8))
    assert not od[0x2003][1].writable


def test_base_node_402_accepts_it() -> None:
    node = canopen.BaseNode402(NODE, str(eds_path()))
    canopen.Network().add_node(node)  # not connected: only so PdoMap.read can subscribe
    assert set(node.tpdo.map) == {1, 2, 3, 4} and set(node.rpdo.map) == {1, 2, 3, 4}
    node.tpdo.read(from_od=True)
    assert [v.index for v in node.tpdo[1].map] == [0x6041, 0x606C] and node.tpdo[1].trans_type == 1
