"""ROS glue shared by the glocal_ros nodes: QoS, service calls, node start-up.

Kept thin on purpose: the experiment's logic lives in ``glocal_ros`` (no
rclpy), the nodes only adapt it onto topics, services and actions.
"""
