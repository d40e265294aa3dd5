"""Readers of autopilot logs: MAVLink tlogs and ArduPilot DataFlash, their compiled scans,
message tables and vehicle clocks.
"""
