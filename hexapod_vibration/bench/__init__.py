"""Benchmarks (make bench): controller cost and the ROS loop."""
