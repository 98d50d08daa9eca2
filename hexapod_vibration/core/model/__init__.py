"""The physical model of the Precision Pointing Hexapod: geometry, plant, sensors, shaker."""
