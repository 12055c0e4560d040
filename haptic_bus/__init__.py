"""haptic_bus: passive virtual walls rendered through a servo drive on a fieldbus.

SI units everywhere inside this package: kg, N, m, s, N/m, N s/m.
"""

__version__ = "0.1.0"
