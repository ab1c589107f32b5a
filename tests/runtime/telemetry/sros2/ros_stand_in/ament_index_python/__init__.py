"""Stand-in for ROS 2's ament_index_python, for running sros2's keystore API without ROS.

pedalwave's sros2 interop test (tests/runtime/telemetry/sros2/run.sh) runs the official sros2 Python
package from a source tree; sros2/__init__.py asks the ament index for its share folder only to
point libxml2's XML catalog at <share>/xml_cache/xhtml-cache.xml (so that policy.xsd's import of
the W3C xml.xsd resolves locally, not over the network). In a source tree that folder is the
package root beside the sros2/ module: run.sh exports it as PEDALWAVE_SROS2_SHARE.
"""
import os


class PackageNotFoundError(KeyError):
    pass


def get_package_share_directory(package_name):
    share = os.environ.get('PEDALWAVE_SROS2_SHARE')
    if package_name != 'sros2' or not share:
        raise PackageNotFoundError(
            f"package '{package_name}' not found (this is pedalwave's stand-in for the ament "
            'index: only sros2, via PEDALWAVE_SROS2_SHARE)')
    return share
