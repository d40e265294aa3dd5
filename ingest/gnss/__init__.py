"""GNSS: broadcast orbits, RINEX parsing, raw-measurement conventions (Android, GSDC), satellite
geometry of observations, single-point positioning, and the check of fixes against observations.
"""
