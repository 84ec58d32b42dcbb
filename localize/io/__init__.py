"""Reading robot data: maps and laser logs from the formats students and engineers meet.

One module per format, all converting to the conventions of the book (metres,
radians, :class:`~localize.OccupancyGrid` with occupancy probabilities, rows =
y, NaN = unknown) and to one log container, :class:`LaserLog`:

* :mod:`localize.io.cmu` — CMU 16-831 homework map (``wean.dat``, P(free)!) and
  logs (cm, laser 25 cm ahead).
* :mod:`localize.io.carmen` — CARMEN logs (``FLASER``, ``ROBOTLASER1``, ``ODOM``,
  ``PARAM``, ``NEFF``; gzip), including SLAM-corrected logs.
* :mod:`localize.io.ros` — ROS ``map_server`` maps (YAML + PGM/PNG).
* :mod:`localize.io.rosbag` — ROS 1 and ROS 2 bags (LaserScan, Odometry, tf) with
  ``rosbags``; writes logs and results (``/amcl_pose``, particle cloud) as bags.
* :mod:`localize.io.tum` — TUM trajectory files (``timestamp x y z qx qy qz qw``) for ``evo``.
* :mod:`localize.io.detect` — format detection from content, :func:`read_map`,
  :func:`read_log`.

Bad input is never returned half-parsed: a malformed record raises
:class:`FormatError` (a ``ValueError``) reading ``file:line: what was expected``;
records of kinds a reader does not use are skipped and counted in one
:class:`ParseWarning` per file (and in ``LaserLog.skipped``).

Examples
--------
>>> from localize import io
>>> sorted(io.MAP_FORMATS), sorted(io.LOG_FORMATS)
(['cmu', 'ros'], ['carmen', 'cmu'])
"""

from ._common import FormatError, LaserLog, ParseWarning, open_text, time_stamp_problems
from .carmen import carmen_angles, read_carmen_log, write_carmen_log
from .cmu import CMU_ANGLES, CMU_MAX_RANGE, CMU_SENSOR_OFFSET, read_cmu_log, read_cmu_map, write_cmu_log, write_cmu_map
from .detect import LOG_FORMATS, MAP_FORMATS, detect_log_format, detect_map_format, read_log, read_map
from .ros import image_to_occupancy, read_pgm, read_ros_map, write_pgm, write_ros_map
from .rosbag import BAG_FORMATS, bag_topics, is_rosbag, read_rosbag, write_result_bag, write_rosbag_log
from .tum import read_tum, write_tum

__all__ = [
    "FormatError", "ParseWarning", "LaserLog", "open_text", "time_stamp_problems",
    "read_cmu_map", "write_cmu_map", "read_cmu_log", "write_cmu_log", "CMU_ANGLES", "CMU_MAX_RANGE",
    "CMU_SENSOR_OFFSET",
    "read_carmen_log", "write_carmen_log", "carmen_angles",
    "read_ros_map", "write_ros_map", "read_pgm", "write_pgm", "image_to_occupancy",
    "detect_map_format", "detect_log_format", "read_map", "read_log", "MAP_FORMATS", "LOG_FORMATS",
    "read_rosbag", "write_rosbag_log", "write_result_bag", "bag_topics", "is_rosbag", "BAG_FORMATS",
    "read_tum", "write_tum",
]
