"""Stand-in for rclpy.utilities (see __init__.py): the rmw implementation a ROS 2 user of Cyclone
DDS runs, rmw_cyclonedds_cpp, unless RMW_IMPLEMENTATION says otherwise (as in ROS 2)."""
import os


def get_rmw_implementation_identifier():
    return os.environ.get('RMW_IMPLEMENTATION', 'rmw_cyclonedds_cpp')
