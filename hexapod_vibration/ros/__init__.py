"""ROS 2 infrastructure shared by the nodes: messages, QoS, parameters, diagnostics, executors."""
