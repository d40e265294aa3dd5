"""navreplay pipeline: earth model and mechanization, synthesizers, estimation, scenarios,
metrics, reports, DVC stage entry points and the ``navreplay`` command line."""
