"""Simulated servo drives whose hardware is the exact m/b handle plant."""
