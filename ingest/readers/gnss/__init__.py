"""Readers of GNSS receiver and GNSS dataset formats: RINEX, NMEA 0183, Android GnssLogger, GSDC
CSVs and libRSF (smartLoc) text.
"""
