"""navreplay pipeline: earth model and mechanization, synthesizers, estimation, scenarios,
metrics, reports, DVC stage entry points and the ``navreplay`` command line."""

from navreplay.pipeline._numba_cache import configure as _configure_numba_cache

_configure_numba_cache()
