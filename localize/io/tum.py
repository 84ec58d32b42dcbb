"""TUM trajectory files: ``timestamp x y z qx qy qz qw``, one pose per line.

The format of the TUM RGB-D benchmark, read by the standard trajectory
evaluation tools (``evo_ape tum reference.tum trajectory.tum``, ``evo_traj``):
space-separated, seconds and metres, the orientation as a unit quaternion with
``w`` last, ``#`` comment lines at the top. A planar pose ``(x, y, theta)`` is
written with ``z = 0`` and the quaternion of a rotation by ``theta`` about z.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry import as_poses, quaternion_to_yaw, yaw_to_quaternion
from ._common import FormatError

__all__ = ["write_tum", "read_tum"]

PathLike = str | os.PathLike


def write_tum(path: PathLike, times: ArrayLike, poses: ArrayLike, comment: str | None = None) -> Path:
    """Write planar poses as a TUM trajectory file.

    Parameters
    ----------
    path : path
    times : array_like, shape (K,)
        Time stamps in seconds.
    poses : array_like, shape (K, 3)
        ``(x, y, theta)`` in metres and radians.
    comment : str, optional
        Written as ``# comment`` lines first.

    Examples
    --------
    >>> p = write_tum(tmp_dir() / "t.tum", [1.5], [[2.0, 3.0, np.pi / 2]])
    >>> print(p.read_text().strip())
    1.500000000 2.000000 3.000000 0.000000 0.000000000 0.000000000 0.707106781 0.707106781
    >>> t, q = read_tum(p)
    >>> t.tolist(), q.round(6).tolist()
    ([1.5], [[2.0, 3.0, 1.570796]])
    """
    t = np.asarray(times, dtype=float).reshape(-1)
    p = as_poses(poses, "poses")
    if p.ndim != 2 or p.shape[0] != t.size:
        raise ValueError(f"poses must have shape ({t.size}, 3), one per time stamp; got {p.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
        raise ValueError("times and poses must be finite to be written as a TUM trajectory")
    out = Path(path)
    lines = [f"# {c}" for c in (comment.splitlines() if comment else [])]
    q = yaw_to_quaternion(p[:, 2])
    for k in range(t.size):
        lines.append(f"{t[k]:.9f} {p[k, 0]:.6f} {p[k, 1]:.6f} 0.000000 0.000000000 0.000000000 "
                     f"{q[k, 2]:.9f} {q[k, 3]:.9f}")
    out.write_text("\n".join(lines) + "\n")
    return out


def read_tum(path: PathLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Read a TUM trajectory file into times ``(K,)`` and planar poses ``(K, 3)``.

    The heading is the rotation about z of each quaternion; a pose that is not
    level (roll or pitch above one degree) is reported as an error, since a
    planar filter cannot use it.
    """
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, None, "no such file")
    rows, lines = [], []
    for n, line in enumerate(p.read_text().splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        f = s.split()
        if len(f) != 8:
            raise FormatError(p, n, f"a TUM line has 8 fields (timestamp x y z qx qy qz qw); got {len(f)}")
        try:
            rows.append([float(v) for v in f])
        except ValueError:
            raise FormatError(p, n, f"expected 8 numbers; got {s[:60]!r}") from None
        lines.append(n)
    if not rows:
        raise FormatError(p, None, "the file holds no poses")
    a = np.array(rows)
    qx, qy, qz, qw = a[:, 4], a[:, 5], a[:, 6], a[:, 7]
    norm = np.sqrt(qx**2 + qy**2 + qz**2 + qw**2)
    if np.any(np.abs(norm - 1) > 1e-3):
        k = int(np.argmax(np.abs(norm - 1)))
        raise FormatError(p, lines[k], f"the quaternion is not a unit quaternion (norm {norm[k]:.6f})")
    tilt = 2 * np.arcsin(np.clip(np.sqrt(qx**2 + qy**2) / norm, 0, 1))
    if np.any(tilt > np.radians(1.0)):
        k = int(np.argmax(tilt))
        raise FormatError(p, lines[k], f"the pose is tilted {np.degrees(tilt[k]):.1f} degrees; expected planar poses")
    yaw = quaternion_to_yaw(a[:, 4:8])
    return a[:, 0], np.column_stack([a[:, 1], a[:, 2], yaw])
