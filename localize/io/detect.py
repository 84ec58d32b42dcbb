"""Recognise file formats from their content, and read any supported map or log."""

from __future__ import annotations

import os
from pathlib import Path

from ..grid import OccupancyGrid
from ._common import GZIP_ERRORS, FormatError, LaserLog, open_text
from .carmen import _KEYWORD, read_carmen_log
from .cmu import read_cmu_log, read_cmu_map
from .ros import read_ros_map

__all__ = ["MAP_FORMATS", "LOG_FORMATS", "detect_map_format", "detect_log_format", "read_map", "read_log"]

PathLike = str | os.PathLike

MAP_FORMATS = ("cmu", "ros")
LOG_FORMATS = ("cmu", "carmen")
_ROS_KEYS = frozenset({"image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode"})


def _head(path: PathLike, n_lines: int = 200) -> list[tuple[int, str]]:
    """The first non-blank lines of a (possibly gzipped) text file with their numbers.

    A damaged gzip stream ends the head early (the reader reports the damage
    with its line); damage before the first line is a :class:`FormatError`.
    """
    out: list[tuple[int, str]] = []
    k = 0
    with open_text(path) as f:
        try:
            for k, line in enumerate(f, start=1):  # noqa: B007
                if line.strip():
                    out.append((k, line.strip()))
                if len(out) >= n_lines:
                    break
        except GZIP_ERRORS as exc:
            if not out:
                raise FormatError(path, k + 1, f"the compressed stream is damaged or truncated ({exc})") from None
    return out


def detect_map_format(path: PathLike) -> str:
    """Name the format of a map file from its content: ``"cmu"`` or ``"ros"``.

    A ROS map is recognised by its YAML keys (``image:``, ``resolution:``,
    ``origin:`` ...; one is enough, so that the reader can name a missing one); a
    CMU/BeeSoft map by its ``robot_specifications->`` header or
    ``global_map[0]:`` line. An image file (PGM/PNG) is rejected with a hint to
    pass its YAML instead.

    Examples
    --------
    >>> p = tmp_text("map.txt", "image: a.pgm\\nresolution: 0.05\\norigin: [0, 0, 0]\\n")
    >>> detect_map_format(p)
    'ros'
    """
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, None, "no such file")
    with open(p, "rb") as f:
        magic = f.read(8)
    if not magic:
        raise FormatError(p, None, "the file is empty; expected a map (CMU .dat or ROS map_server .yaml)")
    if magic[:2] in (b"P5", b"P2") or magic.startswith(b"\x89PNG"):
        cand = p.with_suffix(".yaml")
        hint = f" (there is one: {cand})" if cand.exists() else ""
        raise FormatError(p, None, "this is a map image; pass the map_server YAML that describes it" + hint)
    head = _head(p, 50)
    keys = set()
    for _, line in head:
        if line.startswith("robot_specifications->") or line.startswith("global_map[0]"):
            return "cmu"
        if ":" in line and not line.startswith("#"):
            keys.add(line.split(":", 1)[0].strip())
    if keys & _ROS_KEYS:  # a map_server YAML, perhaps with a key missing: the reader names it
        return "ros"
    first = head[0] if head else (1, "")
    raise FormatError(p, first[0], "cannot tell the map format: expected a CMU 16-831 map "
                                   "('robot_specifications->...' header, 'global_map[0]: ...') or a ROS map_server "
                                   f"YAML ('image:', 'resolution:', 'origin:'); the file starts with {first[1][:60]!r}")


def detect_log_format(path: PathLike) -> str:
    """Name the format of a log from its content: ``"cmu"`` (``O``/``L`` records) or ``"carmen"``.

    Examples
    --------
    >>> p = tmp_text("robot.log", "# a comment\\nPARAM robot_use_laser on\\nODOM 0 0 0 0 0 0 0 h 0\\n")
    >>> detect_log_format(p)
    'carmen'
    """
    head = _head(path, 200)
    for n, line in head:
        tok = line.split()[0]
        if tok.startswith("#"):
            continue
        if tok in ("O", "L"):
            return "cmu"
        if _KEYWORD.match(tok) and len(tok) > 1:
            return "carmen"
        raise FormatError(path, n, "cannot tell the log format: expected CMU 16-831 records ('O ...', 'L ...') or "
                                   f"CARMEN records (FLASER, ODOM, PARAM ...); got {line[:60]!r}")
    raise FormatError(path, None, "the file holds no records (only blank or comment lines)")


def _read(path: PathLike, format: str | None, detect, readers: dict, kwargs: dict):
    """``readers[format](path, **kwargs)``, the format detected from the content when it is None."""
    fmt = format or detect(path)
    if fmt not in readers:
        raise ValueError(f"format must be one of {tuple(readers)} or None (detect); got {format!r}")
    return readers[fmt](path, **kwargs)


def read_map(path: PathLike, format: str | None = None, **kwargs) -> OccupancyGrid:
    """Read a map of any supported format (detected from the content unless ``format`` is given).

    Keyword arguments go to :func:`~localize.io.read_ros_map` or
    :func:`~localize.io.read_cmu_map`.
    """
    return _read(path, format, detect_map_format, {"cmu": read_cmu_map, "ros": read_ros_map}, kwargs)


def read_log(path: PathLike, format: str | None = None, **kwargs) -> LaserLog:
    """Read a log of any supported format (detected from the content unless ``format`` is given).

    Keyword arguments go to :func:`~localize.io.read_cmu_log` or
    :func:`~localize.io.read_carmen_log`.
    """
    return _read(path, format, detect_log_format, {"cmu": read_cmu_log, "carmen": read_carmen_log}, kwargs)
