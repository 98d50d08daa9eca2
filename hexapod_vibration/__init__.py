"""Adaptive notch vibration suppression on a simulated Precision Pointing Hexapod (ROS 2)."""

__version__ = "0.1.0"
