"""Model functions (numba): the physics every INS/GNSS estimator and backend shares."""
