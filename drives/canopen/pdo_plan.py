"""Which PDOs carry the cyclic objects: the mappings to try, in order, for one direction.

Pure planning over what the drive has (:class:`~drives.canopen.inventory.DrivePdo`: its PDOs,
how many entries each mapping record holds, its mapping as it stands); writing a plan, and
falling back to the next when the drive refuses it, is :mod:`drives.canopen.pdo_setup`.

The candidates, in order (each only if it fits and differs from the ones before):

1. **packed**: the objects in order, as few frames as the order allows, each frame within the
   PDO length limit (8 bytes on classical CAN) and the entries its mapping record holds;
2. **one object per PDO**: for a drive that refuses combinations its dictionary cannot show
   (a mapping record with fewer usable entries than it declares, objects tied to one PDO);
3. **the drive's default mapping**: the PDOs whose mapping as it stands (the drive's default
   after NMT reset communication) already carries every object, the fewest of them.  A TPDO
   may carry more (the extra values are decoded and ignored); an RPDO must carry exactly the
   objects (the master would otherwise write values it does not mean into the others every cycle).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

from drives.canopen.inventory import DrivePdo
from drives.canopen.pdo_codec import MAX_PDO_BYTES
from drives.cia402 import OBJECTS, DataType, ObjectSpec

PACKED, ONE_PER_PDO, DEFAULT = "packed", "one object per PDO", "the drive's default mapping"
_UNSIGNED_BY_BITS = {8: DataType.UNSIGNED8, 16: DataType.UNSIGNED16, 32: DataType.UNSIGNED32}


@dataclass(frozen=True)
class Frame:
    """One PDO of a plan: the drive's ``pdo`` carrying ``objects`` in frame order; ``remap``
    False keeps the drive's mapping as it stands (the default-mapping plan)."""

    pdo: DrivePdo
    objects: tuple[ObjectSpec, ...]
    remap: bool = True

    def describe(self) -> str:
        """"TPDO1 (0x6041, 0x606C)"."""
        return f"{self.pdo.label} ({', '.join(object_label(spec) for spec in self.objects)})"


@dataclass(frozen=True)
class MappingPlan:
    """One way to carry the objects: ``how`` (:data:`PACKED`, :data:`ONE_PER_PDO`, :data:`DEFAULT`) and its frames."""

    how: str
    frames: tuple[Frame, ...]

    def describe(self) -> str:
        """"packed: TPDO1 (0x6041, 0x606C), TPDO2 (0x6064)"."""
        return f"{self.how}: {', '.join(frame.describe() for frame in self.frames)}"


def object_label(spec: ObjectSpec) -> str:
    """"0x6041", or "0x60C1:01" for a sub-index."""
    return f"0x{spec.index:04X}" + (f":{spec.subindex:02X}" if spec.subindex else "")


def mapping_word(spec: ObjectSpec) -> int:
    """The mapping entry of ``spec``: index << 16 | subindex << 8 | bit length."""
    return spec.index << 16 | spec.subindex << 8 | 8 * spec.data_type.size


def pack(objects: Sequence[ObjectSpec], capacities: Sequence[int],
         max_bytes: int = MAX_PDO_BYTES) -> list[tuple[int, tuple[ObjectSpec, ...]]] | None:
    """``objects`` in order into frames of at most ``max_bytes`` bytes, frame ``k`` in slot ``k``
    of ``capacities`` (entries each slot holds; a slot of 0 is skipped): ``[(slot, objects)]``,
    or None if the slots run out."""
    frames: list[tuple[int, tuple[ObjectSpec, ...]]] = []
    slot, used = -1, 0
    current: list[ObjectSpec] = []
    for spec in objects:
        size = spec.data_type.size
        if slot < 0 or len(current) >= capacities[slot] or used + size > max_bytes:
            if current:
                frames.append((slot, tuple(current)))
            slot += 1
            while slot < len(capacities) and capacities[slot] < 1:
                slot += 1
            if slot >= len(capacities) or size > max_bytes:
                return None
            current, used = [], 0
        current.append(spec)
        used += size
    if current:
        frames.append((slot, tuple(current)))
    return frames


def plans(objects: Sequence[ObjectSpec], pdos: Sequence[DrivePdo], exact: bool,
          max_bytes: int = MAX_PDO_BYTES) -> tuple[list[MappingPlan], list[str]]:
    """The plans to try in order for ``objects`` over the drive's ``pdos`` of one direction
    (``exact``: RPDOs, see the module docstring), and a reason for each candidate left out."""
    found: list[MappingPlan] = []
    reasons: list[str] = []
    capacities = [pdo.capacity for pdo in pdos]
    packed = pack(objects, capacities, max_bytes)
    if packed is None:
        reasons.append(f"{PACKED}: the drive's {len(pdos)} PDOs of this direction hold "
                       f"{'/'.join(map(str, capacities)) or 'no'} entries of at most {max_bytes} bytes")
    else:
        found.append(MappingPlan(PACKED, tuple(Frame(pdos[slot], frame) for slot, frame in packed)))
    usable = [pdo for pdo in pdos if pdo.capacity >= 1]
    if len(objects) > len(usable):
        reasons.append(f"{ONE_PER_PDO}: {len(objects)} objects, {len(usable)} PDOs that can map one")
    else:
        _add(found, MappingPlan(ONE_PER_PDO, tuple(Frame(pdo, (spec,)) for pdo, spec in zip(usable, objects))))
    default = default_plan(objects, pdos, exact)
    if default is None:
        reasons.append(f"{DEFAULT}: no set of the drive's PDOs carries {'exactly ' if exact else ''}"
                       f"{', '.join(object_label(spec) for spec in objects)}")
    else:
        _add(found, default)
    return found, reasons


def _add(found: list[MappingPlan], plan: MappingPlan) -> None:
    """Append ``plan`` unless an earlier plan maps the same objects into the same PDOs the same way (writing
    the mapping, or taking it as the drive has it: a drive whose mapping is read-only refuses the one and
    accepts the other, even where both carry the same objects)."""
    shape = [(f.pdo.number, f.objects, f.remap) for f in plan.frames]
    if all([(f.pdo.number, f.objects, f.remap) for f in other.frames] != shape for other in found):
        found.append(plan)


def default_plan(objects: Sequence[ObjectSpec], pdos: Sequence[DrivePdo], exact: bool) -> MappingPlan | None:
    """The fewest of ``pdos`` whose mappings as they stand carry ``objects`` (exactly, if ``exact``)."""
    wanted = {(spec.index, spec.subindex) for spec in objects}
    decoded = [(pdo, specs) for pdo in pdos if (specs := decode_mapping(pdo.mapping))]
    for size in range(1, len(decoded) + 1):
        for subset in itertools.combinations(decoded, size):
            carried = [(spec.index, spec.subindex) for _, specs in subset for spec in specs]
            if wanted <= set(carried) and (not exact or sorted(carried) == sorted(wanted)):
                return MappingPlan(DEFAULT, tuple(Frame(pdo, specs, remap=False) for pdo, specs in subset))
    return None


def decode_mapping(words: Sequence[int]) -> tuple[ObjectSpec, ...]:
    """The objects of mapping ``words``, or () if one cannot be decoded whole (not 8/16/32 bits,
    or a known object at another length): objects of drives.cia402 with their own type, others
    as unsigned integers of their length."""
    specs = []
    for word in words:
        index, subindex, bits = word >> 16, word >> 8 & 0xFF, word & 0xFF
        known = OBJECTS.get(index)
        if known is not None and subindex == known.subindex:
            if 8 * known.data_type.size != bits:
                return ()
            specs.append(known)
        elif bits in _UNSIGNED_BY_BITS:
            specs.append(ObjectSpec(index, f"object 0x{index:04X}:{subindex:02X}", _UNSIGNED_BY_BITS[bits], "ro",
                                    subindex=subindex))
        else:
            return ()
    return tuple(specs)
