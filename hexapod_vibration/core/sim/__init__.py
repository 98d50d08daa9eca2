"""The whole loop without ROS: scenarios and the core closed loop."""
