"""The operator's pendant: a live browser interface to a guiding session (``leadthrough
pendant``).

* :mod:`~leadthrough.pendant.backend`: the loop in its own thread, its snapshot and requests
  (the only module that talks to the loop);
* :mod:`~leadthrough.pendant.live_recording`: the last minutes of the session, for the export.
"""
