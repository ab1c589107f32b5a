"""Stand-in for rclpy.validate_namespace (see __init__.py).

ROS 2's rules for a fully qualified namespace (design.ros2.org, "Topic and Service name
mapping"): starts with '/', tokens of [A-Za-z0-9_] separated by single '/', no token starts with
a digit, no trailing '/' except for the root namespace '/'.
"""
import re

from .exceptions import InvalidNamespaceException

_TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*\Z')


def validate_namespace(namespace):
    if namespace == '/':
        return True
    if not namespace.startswith('/'):
        raise InvalidNamespaceException(namespace, "must be absolute (start with '/')")
    if namespace.endswith('/'):
        raise InvalidNamespaceException(namespace, "must not end with '/'")
    for token in namespace[1:].split('/'):
        if not token:
            raise InvalidNamespaceException(namespace, "must not contain '//'")
        if not _TOKEN.match(token):
            raise InvalidNamespaceException(
                namespace, f"token '{token}' must be [A-Za-z0-9_] and not start with a digit")
    return True
