"""What users run, in rooms that import one way (``tests/test_layering.py`` holds them to it):

* ``pipelines.loop``: the closed loop. The controller spec and each controller's facts (``spec``), the
  registry (``controllers``), the MPC and baseline adapters (``mpc`` with ``mpc_setup``, ``baselines``), the
  prediction margins (``margins``), the episode runner (``episode``) and the one episode record every report
  serialises (``record``).
* ``pipelines.logs``: an episode as an MCAP file and back. Message schemas (``schemas``, ``foxglove``,
  ``jsonschema``), the writer (``recorder``), the episode recorder (``recording``), reading (``reader``),
  text review (``review``) and pictures (``plots``).
* ``pipelines.experiments``: many episodes. The paper's cells (``cells``, with the cell and its episode tasks
  in ``tasks``), the sweep split into its log, worker, backends and driver (``log``, ``worker``, ``backends``
  with ``process_backend``, ``sweep`` with ``resume_checks``), the report (``summary``, ``tables``,
  ``report_plots``, ``report``, ``safety_report``), closed-loop calibration (``calibrate``) and synthetic
  training data (``synth``).
* ``pipelines.commands`` and ``pipelines.cli``: the ``crowdmpc`` command line on top of all three.

Shared leaves that import none of the rooms: ``errors``, ``plain_json``, ``version``.
"""
