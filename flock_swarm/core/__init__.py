"""The numerical core: flocking laws, leader models, integrators, graphs, metrics and the run.

Pure NumPy/SciPy functions and frozen parameter dataclasses; nothing here imports rclpy,
plotting or does I/O, so the same code serves the simulator and the ROS nodes.
"""
