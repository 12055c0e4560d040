"""The run-time controller: scenes, the passivity gate, the cycle, its observer, record and clocks."""
