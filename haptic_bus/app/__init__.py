"""The application: command line, profiles, demo rig, runner, reports and plots -- and the control
process a run is.

A run (``haptic-bus run``, :func:`haptic_bus.run` for one axis or several, the
demo) is one process that cycles, and two children that work out of its way.  In CPython only
one thread runs Python at a time, so every thread that formats, draws, judges or decodes a frame
it will throw away holds the cycle up for as long as it runs; the layout below keeps the control
thread the only one that runs Python while the drives are enabled.

Who does what
-------------

``MainThread`` of the control process -- the control thread
    Owns the process's one bus handle (CANopen: one python-can bus, one canopen ``Network`` for
    the drive(s) and the controller's own node; Modbus: one client).  Each cycle: wait for the
    deadline (:class:`~haptic_bus.control.clock.RealClock`: sleep, then spin); SYNC; receive until
    every axis' TPDOs are in, or the cycle's timeout; the wall force, the clamp, the passivity
    layer; RPDOs; every ``heartbeat/T`` cycles the controller's heartbeat, so that it stops when
    the cycle stops (:meth:`drives.canopen.heartbeat.HeartbeatProducer.from_cycle`).  Frames that
    are not the cycle's are dispatched from that same receive without blocking: SDO requests to
    the controller's node (gated wall uploads, :mod:`haptic_bus.node.controller_node`), whose
    answers it sends; EMCY and heartbeats to the drive's events; those read before the SYNC are
    handed on right after it, while the drives answer, so that the SYNC leaves on time, and what they
    say is checked before the TPDOs are waited for (a drive that faulted and went silent trips then:
    :meth:`drives.canopen.sync_cycle.SyncCycle.drain`).  It appends one row per axis to a
    ring in shared memory (one ``struct.pack_into`` and a counter store) and, with a bus log, each
    frame it sends or receives to another ring (the link's tap).  Pre-flight runs this same cyclic
    path, with zero torque, before the drives are enabled, and goes on running it while
    ``preflight-judge`` works.
``preflight-judge`` -- before the drives are enabled only
    Judges the scene at the loop delay pre-flight measured (the coupled gate on a sphere: seconds)
    while the control thread keeps the drives' RPDOs and the heartbeat going at zero torque
    (:func:`haptic_bus.app.preflight.while_cycling`); it ends before the enable.  Beside a
    SCHED_FIFO control thread it runs at SCHED_FIFO 1, as the other threads do (an ordinary
    thread preempted while it held the GIL held the cycle up 80-173 ms on a loaded machine); a
    stop during its judgement leaves it judging unwaited for, put back to an ordinary thread.
``verdict-collect``, ``verdict-feed`` -- the upload judge's executor threads
    concurrent.futures' two threads of the judge's process pool, blocked on its pipes; they run
    only while an upload is judged (:mod:`haptic_bus.node.verdicts`).
``hb-write-watch`` -- the writer's alarm
    Blocked in ``read`` on a pipe of its own from the writer; it runs once, if the writer cannot
    write the folder (a full disk, the folder deleted), to ask the run to stop at the next cycle
    boundary (:mod:`haptic_bus.app.run_writer`).
``heartbeat-<node>``, ``canopen-notify`` -- outside the cyclic phase only
    Commissioning, SDO access and the disabling walk: canopen's notifier reads the bus and the
    heartbeat thread keeps the drives' consumers fed.  Entering the cyclic phase silences the
    heartbeat thread and stops the notifier; leaving it brings the heartbeat thread back.
``haptic-bus-writer`` (``hb-writer`` in ``/proc``) -- a child process, spawned before commissioning
    Drains the rings every 50 ms: ``record.csv`` (``record-<axis>.csv`` for several axes), ``bus.asc``
    (python-can's ``ASCWriter``), ``run.json`` kept current and replaced atomically, the live view
    (:mod:`haptic_bus.app.run_writer`, :mod:`haptic_bus.app.writer_process`).  It ends after a last
    drain when the control process ends, however it ends: a ``kill -9`` of a run leaves every
    axis' record to within 0.1 s of the kill.
``hb-writer`` -- a thread instead, when the drive is on an in-process bus
    The same writer loop over the same pipe and rings, for a run whose drive runs in the control
    process (python-can's ``virtual`` bus, the lock-step bus: the demos, the pytest plugin's
    simulated drive).  That process already runs the drive's code beside the cycle, a kill ends
    the drive with the run, and a spawned writer costs an interpreter and its imports (about
    0.25 s of CPU with python-can's ASC writer, measured on this project's 2-core machine), a
    large part of a short test's run; a ``kill -9`` loses the rows of the last drain interval (50 ms).
the judge -- a child process, spawned before the first cycle
    Judges a committed upload with the gate (1-D or coupled); the control thread collects the
    verdict once a cycle without waiting, adopts the judged scene at a cycle boundary and
    answers the SDO download then (:mod:`haptic_bus.node.verdicts`).

What crosses between them
-------------------------

To the writer: the rings (no system call, no lock: the writer polls the counters; a writer a
whole ring behind loses the oldest rows and counts them) and, for each event (an upload, an
alarm, the end), one pickled message on a pipe; back, once, a write that failed.  To the judge: the staged walls, the running
scene and the gate, pickled once per upload; back: the scene and the decision.  Nothing crosses
back into the cycle but the judge's verdict, read at a cycle boundary.

Why the cycle is not held up
----------------------------

While the drives are enabled no other thread of the control process runs Python: the writer
and the judge are processes, the executor threads wait in ``select`` and the writer's alarm in
``read``, the heartbeat thread and
canopen's notifier are parked (a drive on an in-process bus is the exception: its own code, and
so the writer's thread, share the process with the cycle).  Heavy imports (matplotlib, scipy) happen in the children, before
pre-flight or after the last cycle (the pictures are drawn when the run has ended);
``gc.freeze()``, a lowered GIL switch interval and, where the OS grants them, ``SCHED_FIFO``,
one CPU and locked memory come with the real-time session (:mod:`haptic_bus.app.realtime`):
without real-time scheduling no Python loop keeps its start lateness near the bare clock's
beside other work, so it is asked for by default.  ``tests/test_architecture.py`` checks that one thread
touches the bus handle of a 1-axis and a 3-axis run; ``tests/test_run_threads.py`` which threads
exist while cycling.  The process starts no thread it does not name: ``haptic-bus`` asks numpy's and
scipy's BLAS for one thread before it imports them (:mod:`haptic_bus.app.blas_threads`; their pools
had two unnamed threads), and ``tests/test_run_crash.py`` reads ``/proc`` of a cycling run for a
thread the OS shows by the process's name.  ``haptic-bus bench --only realtime`` measures the result side by side: the
control process's CPU against python-can's floor for the same frames, its lateness against the
bare clock.
"""
