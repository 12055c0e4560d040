"""The simulated drive as a real CANopen slave (canopen LocalNode on a python-can bus)."""
