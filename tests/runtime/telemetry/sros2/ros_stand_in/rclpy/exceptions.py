"""Stand-in for rclpy.exceptions (see __init__.py)."""


class InvalidNamespaceException(ValueError):
    def __init__(self, namespace, reason):
        super().__init__(f"Invalid namespace '{namespace}': {reason}")
