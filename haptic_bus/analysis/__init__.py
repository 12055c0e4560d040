"""The passivity analysis of the sampled-data wall loop: plant, responses, criterion, limits.

Pure numerics (numpy; mpmath only for a pole within round-off of the unit circle; scipy only inside
the time-domain energy check and the design tools, and
imported there lazily or by those modules alone): nothing here imports bus code.  SI units
throughout.  Modules, one job each:

* ``loop`` (the loop's parameters: :class:`~haptic_bus.analysis.loop.DeviceLoop`,
  :class:`~haptic_bus.analysis.loop.WallLoop`), ``velocity`` (which velocity the drive reports),
  ``plant`` (exact ZOH solution), ``sampled_loop`` (the period map and the closed-loop matrix);
* ``trig``, ``theta_complex``, ``alias_sum`` (the alias function ``g``: what sampling adds to the
  continuous loop), ``frequency`` (``T_fund`` and the impedance), ``characteristic`` (the closed
  loop's characteristic function in ``z - 1``), ``poles``;
* ``theta_search`` (the grid and the joint zoom), ``criterion`` (the verdict), ``limits`` (passive intervals);
* ``energy`` (the time-domain arbiter), ``out_of_band`` (the exposure to forces above Nyquist);
* ``resolution`` (a device's encoder resolution and Coulomb friction), ``quantisation`` (their
  condition on a wall: per crossing, or a drift),
  ``quantised_loop`` (its arbiter: the loop with counts and Coulomb sticking, simulated exactly);
* ``closed_form``, ``design`` (the seed's figures), ``tables`` (the README table), ``check`` (the report);
* ``coupled_loop``, ``coupled``, ``coupled_limits``, ``coupled_energy`` (several axes coupled
  through the hand); ``can_timing`` (the CAN bit-time model: frame times, bus load);
* ``transmission``, ``two_mass``, ``two_mass_criterion``, ``two_mass_energy``, ``two_mass_check`` (a handle
  on a transmission that is not rigid: the motor senses and drives, the operator is at the handle;
  docs/physics/transmission.md).

The parameter vocabulary
------------------------

One quantity, one name.  The loop objects of the analysis use the seed's symbols, so that its
formulas read as printed; everything a user types (:func:`haptic_bus.check_passivity`, a
profile's keys, the command lines' flags, a scene object's fields, the simulator's truth) uses
the word:

==========  ===============  ========  =====================================================
symbol      word             unit      what
==========  ===============  ========  =====================================================
``m``       ``mass``         kg        the handle's mass (profile ``[device] mass``)
``b``       ``friction``     N s/m     its viscous friction, effective (``[device] friction``)
``T``       ``period``       s         the sampling period (``[loop] period``)
``K``       ``stiffness``    N/m       a wall's stiffness (a scene object's ``stiffness``)
``B``       ``damping``      N s/m     a wall's damping (a scene object's ``damping``)
``D``       ``delay``        samples   the loop delay, real, ``D = d + delta`` (``[loop] delay``)
-           ``velocity``     -         the model of the velocity the drive reports (0x606C)
==========  ===============  ========  =====================================================

And the loop's names, each for one thing:

* :class:`~haptic_bus.analysis.loop.DeviceLoop` (``m, b, T, delay, velocity``): the loop a
  device runs its walls in, with no wall; what the gate holds.  ``.wall(K, B)`` gives
* :class:`~haptic_bus.analysis.loop.WallLoop` (``m, b, T, K, B, delay, velocity``): one wall in
  that loop, validated; what every criterion here judges.
* ``LoopTiming`` (:mod:`haptic_bus.profile.device`, ``period, timing, delay``): a profile's
  ``[loop]`` table as read, where ``T`` and ``D`` come from (``timing`` says how the drive
  applies a target); ``Profile.device_loop()`` turns a profile into its ``DeviceLoop``.
* ``DeviceParameters`` (:mod:`sim_drive.parameters`, ``mass, friction, period, ...``): the simulated
  drive's hidden truth (plant, scaling, Coulomb friction, noise); the controller and this
  analysis never see it.
"""
