"""The passivity analysis of the sampled-data wall loop: plant, responses, criterion, limits.

Pure numerics (numpy; mpmath only for a pole within round-off of the unit circle; scipy only inside
the time-domain energy check and the design tools, and
imported there lazily or by those modules alone): nothing here imports bus code.  SI units
throughout.  Modules, one job each:

* ``loop`` (the loop's parameters), ``velocity`` (which velocity the drive reports),
  ``plant`` (exact ZOH solution), ``sampled_loop`` (the period map and the closed-loop matrix);
* ``trig``, ``theta_complex``, ``alias``, ``frequency`` (``T_fund`` and the impedance),
  ``characteristic`` (the closed loop's characteristic function in ``z - 1``), ``poles``;
* ``theta_search`` (the grid and the joint zoom), ``criterion`` (the verdict), ``limits`` (passive intervals);
* ``energy`` (the time-domain arbiter), ``aliasing`` (out-of-band exposure);
* ``closed_form``, ``design`` (the seed's figures), ``tables`` (the README table), ``check`` (the report).
"""
