"""Writers of foreign log formats from canonical tables (ROS 2 MCAP, ROS 1 bag, RINEX, MAVLink
tlog, CSV).

The synthesizers in ``pipeline.synth`` produce canonical tables and hand them to these
writers, so synthesized datasets arrive as the files users' own tools open.
"""
