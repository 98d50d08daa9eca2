"""The loop's protocol without ROS: runs and sample sequences, command pairing, signal ranges."""
