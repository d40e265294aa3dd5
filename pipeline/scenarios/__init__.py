"""Scenarios: outages, reduced satellite counts and faults as transformations of the tables.

Applied before the replay loop, never inside a filter (architecture section 4):
``config`` (the ``scenarios`` section of params.yaml), ``windows`` (placement), ``satellites``
(selection policies, single-point re-fixes), ``faults`` (the catalogue's F1-F12),
``apply`` (``apply_scenario``), ``criteria`` (the catalogue's pass criteria, checked).
"""
