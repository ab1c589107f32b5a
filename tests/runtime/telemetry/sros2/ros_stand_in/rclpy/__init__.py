"""Stand-in for the three rclpy helpers that sros2's keystore API imports (no ROS 2 in Debian 12).

Only what sros2.keystore uses: rclpy.validate_namespace.validate_namespace (enclave names),
rclpy.exceptions.InvalidNamespaceException, rclpy.utilities.get_rmw_implementation_identifier
(sros2 grants the ros_discovery_info topic for the rmw implementations that use it).
"""
