"""``haptic-bus validate``: does the closed loop on the device behave as the gate's model predicts?

Bus-free parts of the command (issue 27, item 2); :mod:`haptic_bus.app.validate_run` runs them
through the one runtime's cycle and :mod:`haptic_bus.app.validate_cli` is the command.

- :mod:`~haptic_bus.validate.probe`: the probe, a periodic flat multisine added to a gentle,
  gate-judged spring and damper that holds the handle about its rest position, as a scene the
  controller renders;
- :mod:`~haptic_bus.validate.model`: the responses the model predicts, exact for the sampled loop
  (the analysis package's period map, the profile's delay and velocity model);
- :mod:`~haptic_bus.validate.spectra`: the measured responses per excited frequency, with their
  uncertainty from the scatter across the probe's periods;
- :mod:`~haptic_bus.validate.two_mass`: the exact sampled plant of a handle behind a compliant
  transmission, for the fit and for a profile that states one;
- :mod:`~haptic_bus.validate.circle`: ``z`` and ``z - 1`` on the unit circle, which both plants use;
- :mod:`~haptic_bus.validate.departures`: the departures fitted (extra delay, resonance, filter,
  mass and friction), each with its uncertainty, and the verdict.
"""
