"""The operator's pendant: a live browser interface to a guiding session (``leadthrough
pendant``).

* :mod:`~leadthrough.pendant.backend`: the loop in its own thread, its snapshot and requests
  (the only module that talks to the loop); :mod:`~leadthrough.pendant.live_recording`: the
  last minutes of the session, for the export;
* :mod:`~leadthrough.pendant.app`: the web app (viser), with
  :mod:`~leadthrough.pendant.status_view`, :mod:`~leadthrough.pendant.scene_view`,
  :mod:`~leadthrough.pendant.robot_scene`, :mod:`~leadthrough.pendant.controls` and
  :mod:`~leadthrough.pendant.transitions`;
* teach: :mod:`~leadthrough.pendant.taught_points`, :mod:`~leadthrough.pendant.export`;
* the simulator: :mod:`~leadthrough.pendant.simulated`, :mod:`~leadthrough.pendant.push`.
"""
