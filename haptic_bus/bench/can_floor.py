"""python-can's floor: the same cycle's frames with nothing but python-can, in a process of its own.

The yardstick of issue 26: what one controller cycle on a CAN bus costs when python-can alone does
it -- one bus handle (receive filters on the drives' TPDO COB-IDs, as the controller sets them), the
project's clock (:class:`~haptic_bus.control.clock.RealClock`, sleep then spin) under the same OS
settings (:func:`~haptic_bus.app.realtime.realtime_session`), and per cycle: SYNC out, every
drive's TPDOs of the cycle in, one RPDO per drive out (zero torque, controlword 0: a drive that is
not enabled stays so), and the controller node's heartbeat every heartbeat period.  No decoding
beyond the COB-ID, no controller, no record.

It runs as ``python -m haptic_bus.bench.can_floor CONFIG_JSON`` so that its CPU time is its own, against
drives some other program has commissioned (the benchmark starts it before a controller run against the
same simulated drives, its imports done before any CPU hog starts, and tells it ``go`` on stdin right
after that run: their PDO mapping and heartbeat consumer are set, and this floor keeps feeding both; again
after the next run of the same cycle, if there is one), and prints one JSON object per ``go``: the share of a core the
process used over the loop, the start lateness percentiles (s), the overruns, and the cycles whose
TPDOs did not all arrive within the period.
"""

from __future__ import annotations

import json
import resource
import sys
import time
from dataclasses import dataclass
from typing import Any

import can
import numpy as np

from drives.bus_config import open_bus
from drives.cia301 import HEARTBEAT_BASE, NMT_COB_ID, SYNC_COB_ID, NmtState
from drives.udp_multicast import standard_filters
from haptic_bus.app.realtime import RealtimeSettings, realtime_session
from haptic_bus.control.clock import RealClock

TPDO_BASES = (0x180, 0x280, 0x380, 0x480)  # CiA 301 default COB-IDs of TPDO1..4, plus the node id
RPDO1_BASE = 0x200
NMT_START = 0x01
READY = "ready"  # the line this process prints once imported (the benchmark starts it early: module docstring)


@dataclass(frozen=True)
class FloorConfig:
    """One floor run: ``bus`` (python-can keyword arguments), the drives' ``node_ids``, how many
    TPDOs each sends per SYNC (``tpdos``), the RPDO's length in bytes (``rpdo_bytes``: controlword
    and target torque, 4), ``period`` and ``duration`` (s), the controller node's id and heartbeat
    period (s; 0: none)."""

    bus: dict[str, Any]
    node_ids: tuple[int, ...]
    tpdos: int
    period: float
    duration: float
    rpdo_bytes: int = 4
    controller_node_id: int = 127
    heartbeat: float = 0.02

    @classmethod
    def from_json(cls, text: str) -> FloorConfig:
        """The configuration the benchmark passes on the command line."""
        raw = json.loads(text)
        raw["node_ids"] = tuple(raw["node_ids"])
        return cls(**raw)


def floor_run(config: FloorConfig) -> dict[str, Any]:
    """Cycle ``config.duration`` s at ``config.period`` with python-can alone; the figures (module docstring)."""
    tpdo_ids = {base + node: node for node in config.node_ids for base in TPDO_BASES}
    expected = config.tpdos * len(config.node_ids)
    cycles = max(1, round(config.duration / config.period))
    beat_every = max(1, round(config.heartbeat / config.period)) if config.heartbeat > 0 else 0
    sync = can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False)
    rpdos = [can.Message(arbitration_id=RPDO1_BASE + node, data=bytes(config.rpdo_bytes), is_extended_id=False)
             for node in config.node_ids]
    beat = can.Message(arbitration_id=HEARTBEAT_BASE + config.controller_node_id, data=bytes([NmtState.OPERATIONAL]),
                       is_extended_id=False)
    bus = open_bus(**config.bus)
    missed = 0
    try:
        bus.set_filters(standard_filters(set(tpdo_ids)))
        for node in config.node_ids:
            bus.send(can.Message(arbitration_id=NMT_COB_ID, data=bytes([NMT_START, node]), is_extended_id=False))
        settings = RealtimeSettings()
        clock = RealClock(config.period, capacity=cycles + 1, spin=settings.spin)
        with realtime_session(settings):
            started = resource.getrusage(resource.RUSAGE_SELF)
            wall = time.perf_counter()
            for k in range(cycles):
                clock.wait_next(k)
                bus.send(sync)
                deadline = time.perf_counter() + config.period
                got = 0
                while got < expected:
                    remaining = deadline - time.perf_counter()
                    msg = bus.recv(remaining if remaining > 0.0 else 0.0)
                    if msg is None:
                        missed += 1
                        break
                    if msg.arbitration_id in tpdo_ids:
                        got += 1
                for rpdo in rpdos:
                    bus.send(rpdo)
                if beat_every and k % beat_every == 0:
                    bus.send(beat)
            wall = time.perf_counter() - wall
            used = resource.getrusage(resource.RUSAGE_SELF)
    finally:
        bus.shutdown()
    cpu = (used.ru_utime - started.ru_utime) + (used.ru_stime - started.ru_stime)
    late = clock.lateness()
    p50, p99, p999 = np.percentile(late, [50, 99, 99.9])
    return {"cycles": cycles, "core_share": cpu / wall, "lateness_s": {"p50": float(p50), "p99": float(p99),
            "p99.9": float(p999), "max": float(late.max())}, "overruns": clock.overruns, "missed_cycles": missed}


def main(argv: list[str]) -> int:
    """``python -m haptic_bus.bench.can_floor CONFIG_JSON``: :data:`READY` on a line once imported, then, for
    each line ``go`` on stdin, one floor run's figures as one JSON line (the benchmark measures one process beside
    several controller runs of the same cycle), until stdin ends (exit 1 without a run: the benchmark ended first)."""
    config = FloorConfig.from_json(argv[0])
    print(READY, flush=True)
    runs = 0
    for line in sys.stdin:
        if line.strip() != "go":
            break
        print(json.dumps(floor_run(config)), flush=True)
        runs += 1
    return 0 if runs else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
