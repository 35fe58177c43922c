"""The ROS 2 nodes: thin plumbing between messages and the numerical core."""
