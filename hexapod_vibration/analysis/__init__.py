"""Bags to reports: bag I/O, tone levels, report.json, figures (no rclpy import)."""
