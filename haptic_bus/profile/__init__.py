"""Operator profiles: one TOML format, one schema, read once (the base layer of haptic_bus).

Below the controller and above the analysis, so both the controller (:mod:`haptic_bus.app`) and
the simulated drive (:mod:`sim_drive`) read profiles through it:

* :mod:`~haptic_bus.profile.reader`: one table at a time, typed fields, one-line errors that name
  the file, the dotted field, the value and the allowed range; unknown keys refused;
* :mod:`~haptic_bus.profile.files`: shipped profiles by name, others by path;
* :mod:`~haptic_bus.profile.device`: ``[device]`` and ``[loop]``;
* :mod:`~haptic_bus.profile.link`: an ``[[axes]]`` table's ``node_id`` or ``unit_id``;
* :mod:`~haptic_bus.profile.identification`: ``[identification]``, what ``haptic-bus identify`` wrote;
* :mod:`~haptic_bus.profile.operator`: ``[operator_model]``, the simulated operator;
* :mod:`~haptic_bus.profile.plant`: those tables of a one-axis profile read together, the part
  the controller's view and the simulator's view share;
* :mod:`~haptic_bus.profile.scene`: the controller's ``[limits]`` and ``[[scene.objects]]``, checked
  here so the simulator refuses their mistakes with the same line.

The controller builds its scene from those tables and reads its policies (gate, safety, passivity,
supervisor, start) in :mod:`haptic_bus.app.profiles` (a module per kind: ``one_axis``, ``axes``), which
need the control layer's types.
"""
