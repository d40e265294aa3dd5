"""Experiments of the papers: pure functions from tables and params to tables and figures.

``navreplay experiment NAME`` (``pipeline.stages.experiment``, wired into dvc.yaml) writes
deterministic JSON/CSV tables (``{"rows": [...]}`` plus extras) and PNG figures for the
reports under ``datasets/<id>/experiments/<NAME>/``:

- ``vehicle_bands`` (paper 003, car_speed_ramp): ``bands.{json,csv}`` one row per scenario
  (``nominal``, ``outages``), filter, subset (``all``, ``in_outage``) and true-speed band with
  ``pos_h_rms_m``, ``heading_rms_rad``, ``course_rms_rad``, ``slip_rms_rad``,
  ``speed_rms_mps``, ``pos_h_max_m``, ``samples``, ``dynamic_share``;
  ``acceptance.{json,csv}`` (switched and IMM against the better single model per band,
  ``all_ok``); ``bands.png``.
- ``vehicle_switch_speed`` (paper 003, no tables: held-out realizations of car_speed_ramp):
  ``calibration.{json,csv}`` dynamic - kinematic horizontal RMS per scenario and speed band
  with its interval, ``dynamic_ok``, and the chosen ``speed_up_mps`` / ``speed_down_mps``;
  ``calibration_seeds.{json,csv}`` the per-seed band rows; ``switch_note.md``.
- ``fwekf_convergence`` (paper 004, fwekf_reference + fwekf_reference_noise_free):
  ``convergence.{json,csv}`` one row per case (``noisy``, ``noise_free``), tuning
  (``declared``, ``paper_r``) and filter (``lc_ekf``, ``fwekf``): errors at 5/10/20/40 s,
  settle times below 0.5 m and 0.02 m/s, RMS after 20 s, alpha median and max, the paper's
  statement; ``convergence.png``.
- ``fwekf_faults`` (paper 004, seoul_campus_cw): ``faults.{json,csv}`` one row per scenario
  (``nominal``, ``F7_multipath_burst``, ``F8_optimistic_accuracy``, ``outages``) and filter.

- ``tractor_cascaded`` (paper 000, simulated in closed loop; no tables): the cascaded EKF,
  UKF and hybrid steering the tractor, Monte Carlo over seeds with GPS outages; the folder's
  layout is documented in ``tractor_cascaded.artifacts``.

- ``vehicle_smartloc`` (the real smartLoc drive, tables from ``navreplay ingest`` of its two
  text files; not a dvc stage, the data lives outside the repository): ``smartloc.{json,csv}``
  with the layout of ``bands`` plus whole-drive rows (``band_hi_mps`` null) and a
  ``spp_fixes`` row (the least-squares fixes themselves).
"""
