"""Readers of ROS logs: MCAP, ROS 1 bags, rosbag2, and the ROS message decoding and conversion
they share.
"""
