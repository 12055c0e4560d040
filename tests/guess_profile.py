"""A one-drive profile of guesses, as a user writes one before ``haptic-bus identify`` measures
the handle: not a test module.  The truth is the simulated drive's; the tests that identify it
write this profile with their own guesses (:func:`guess_profile`)."""

from __future__ import annotations

from pathlib import Path

TEMPLATE = """\
# {comment}
[profile]
name = "{name}"
operator = "commissioning engineer"
task = "{task}"
description = "{description}"

[device]
mass = {mass!r}                       # kg: a guess
friction = {friction!r}                   # N s/m: a guess
friction_source = "datasheet"
velocity = "{velocity}"               # what the controller believes 0x606C is
velocity_per_count = 1e-6
position_per_count = 1e-7
rated_torque = {rated_torque!r}
force_per_torque = 50.0
max_torque_permille = 3000

[loop]
period = {period!r}
timing = "cia402"

[limits]
force_limit = {force_limit!r}

[gate]
safety_margin = 0.0
bandwidth = "warn"

[scene]
objects = []

[safety]
heartbeat_ms = 100               # a loaded test machine: the watchdogs guard a dead master, not a busy one
consumer_ms = 2000
"""


def guess_profile(path: Path, *, comment: str, name: str, task: str, description: str, mass: float, friction: float,
                  velocity: str, rated_torque: float, period: float, force_limit: float) -> Path:
    """Write the profile to ``path``: the guessed ``mass`` (kg) and ``friction`` (N s/m), the
    velocity model the controller believes, ``rated_torque`` (N m), ``period`` (s) and
    ``force_limit`` (N); 1 um/s and 0.1 um per count, 50 N per N m, an empty scene."""
    path.write_text(TEMPLATE.format(comment=comment, name=name, task=task, description=description, mass=mass,
                                    friction=friction, velocity=velocity, rated_torque=rated_torque, period=period,
                                    force_limit=force_limit))
    return path
