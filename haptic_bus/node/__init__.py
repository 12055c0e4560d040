"""The controller on the bus: its CANopen node, serving gated wall uploads over SDO
(:mod:`~haptic_bus.node.controller_node`), and the client that uploads to it
(:mod:`~haptic_bus.node.upload`, ``haptic-bus upload``).

A layer of its own above :mod:`haptic_bus.control` (which stays free of bus libraries) and below
:mod:`haptic_bus.app`.
"""
