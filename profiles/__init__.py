"""Operator parameter profiles shipped with haptic_bus (TOML files in this folder)."""
