"""Paper 000's experiment: the cascaded EKF, UKF and hybrid steering the tractor in closed loop.

``runs`` (scenarios, Monte Carlo, per-run scalars, aggregation), ``comparison`` (the paper's
claims beside ours, mechanism checks), ``figures``, ``artifacts`` (the output folder:
``navreplay experiment tractor_cascaded --out datasets/tractor_straight/experiments/
tractor_cascaded``; its layout is documented there).
"""
