"""The operator's pendant: a live browser interface to a guiding session (``leadthrough
pendant``).

* :mod:`~leadthrough.pendant.backend`: the loop in a process of its own, its snapshot and
  requests (the only module that talks to the loop), with
  :mod:`~leadthrough.pendant.messages` (requests, snapshot), :mod:`~leadthrough.pendant.
  shared_state` (lock-free shared memory) and :mod:`~leadthrough.pendant.loop_process` (the
  loop's process: the one guiding loop, :func:`leadthrough.session.loop.run`);
  :mod:`~leadthrough.pendant.live_recording`: the last minutes of the session, for the export;
* :mod:`~leadthrough.pendant.app`: the web app (viser), with
  :mod:`~leadthrough.pendant.status_view`, :mod:`~leadthrough.pendant.scene_view`,
  :mod:`~leadthrough.pendant.robot_scene`, :mod:`~leadthrough.pendant.controls` and
  :mod:`~leadthrough.pendant.transitions`;
* teach: :mod:`~leadthrough.pendant.taught_points`, :mod:`~leadthrough.pendant.export`;
* the simulator: :mod:`~leadthrough.pendant.simulated`, :mod:`~leadthrough.pendant.push`.
"""
