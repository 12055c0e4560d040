"""The distribution version (one place: haptic_bus.__version__ and the CANopen identity read it)."""

__version__ = "0.2.0"
