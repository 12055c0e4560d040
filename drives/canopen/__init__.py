"""The CiA-402 master over CANopen (canopen + python-can)."""
