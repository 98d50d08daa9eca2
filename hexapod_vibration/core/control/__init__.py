"""Control laws, filters and identification (no ROS import)."""
