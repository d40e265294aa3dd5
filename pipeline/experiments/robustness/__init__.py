"""Issue 22's robustness sweep on generated drives: ``grid`` (IMU grades x fix errors x
covariance x rates, the drive of a cell), ``measure`` (the references and a run's errors),
``sweep`` (every filter on every cell, the acceptance points, the tables)."""
