"""Fieldbus masters behind one Drive interface, and the CiA-402 protocol tables."""

from __future__ import annotations

import logging

# A library's logging (the logging HOWTO): drives' records go where the program's logging sends them, and
# nowhere (not logging.lastResort's stderr) in a program that configures none; the command line configures its own.
logging.getLogger(__name__).addHandler(logging.NullHandler())
