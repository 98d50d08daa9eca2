"""Pure numerical core: no rclpy or ROS message imports."""
