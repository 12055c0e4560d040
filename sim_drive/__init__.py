"""Simulated servo drives whose hardware is the exact m/b handle plant."""

from __future__ import annotations

import logging

# A library's logging (the logging HOWTO): sim_drive' records go where the program's logging sends them, and
# nowhere (not logging.lastResort's stderr) in a program that configures none; the command line configures its own.
logging.getLogger(__name__).addHandler(logging.NullHandler())
