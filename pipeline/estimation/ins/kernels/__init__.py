"""Compiled (numba, ``cache=True``) replay loops and the numerics both backends share."""
