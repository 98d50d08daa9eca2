"""The rclpy nodes (thin: parameters and messages in, one call into the core, messages out)."""
