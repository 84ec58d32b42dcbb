"""ROS ``map_server`` maps: a YAML description plus a PGM or PNG image.

A map is a small YAML file such as::

    image: willow-2010-02-18-0.10.pgm
    resolution: 0.100000          # metres per pixel
    origin: [0.0, 0.0, 0.0]       # pose of the lower-left pixel (x, y, yaw)
    negate: 0
    occupied_thresh: 0.65
    free_thresh: 0.196
    mode: trinary                 # optional: trinary (default), scale or raw

and an image whose **first row is the top of the map** (largest y). Following
``map_server``, a pixel's occupancy is ``p = (255 - v) / 255`` for a grey value
``v`` (``v / 255`` with ``negate: 1``; colour pixels use the mean of their
channels). Then

* ``trinary``: ``p > occupied_thresh`` is occupied, ``p < free_thresh`` free,
  anything between unknown;
* ``scale``: the same, but values between the thresholds keep an intermediate
  occupancy ``(p - free_thresh) / (occupied_thresh - free_thresh)``
  (fully transparent pixels are unknown);
* ``raw``: the pixel value itself is the occupancy in percent (0-100), larger
  values are unknown.

**A real-world wrinkle.** Maps edited by hand often have walls painted mid-grey.
In the Willow Garage map the walls are 100-200, i.e. ``p`` between 0.22 and 0.61:
strictly by its own thresholds most walls are *unknown*, not occupied. A range
sensor cannot see through them either way (an :class:`~localize.OccupancyGrid`
treats unknown cells as obstacles for ray casting by default), but plots and
anything that distinguishes the two classes will be off. :func:`read_ros_map`
therefore exposes the thresholds and mode (override the YAML's values) and
``not_free="occupied"``, which turns every cell that is not free into an
obstacle.
"""

from __future__ import annotations

import io as _io
import os
import re
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._checks import check_grid
from ..grid import OccupancyGrid
from ._common import FormatError, ParseWarning
from ._yaml import load_yaml_mapping

__all__ = ["read_ros_map", "write_ros_map", "read_pgm", "write_pgm", "parse_map_yaml", "image_to_occupancy"]

PathLike = str | os.PathLike

_MODES = ("trinary", "scale", "raw")
#: The largest grey value of a 16-bit image (PGM maxval, PNG I;16); 8-bit images end at 255.
_MAX_GREY_16 = 65535


# ----------------------------------------------------------------------------- PGM
def _pgm_header(p: Path, buf: bytes) -> tuple[bytes, int, int, int, int]:
    """Magic, width, height, maxval and the offset after the header, checked with the line of a bad field."""
    magic = buf[:2]
    if magic not in (b"P5", b"P2"):
        raise FormatError(p, 1, f"expected a PGM image starting with 'P5' (binary) or 'P2' (plain); got {magic!r}")
    pos, fields = 2, []  # width, height, maxval separated by whitespace; '#' comments to end of line
    for tok in re.finditer(rb"\s*(?:#[^\n\r]*[\n\r]?\s*)*([^\s#]*)", buf[2:]):
        start, pos = 2 + tok.start(1), 2 + tok.end(1)
        if start == pos:
            raise FormatError(p, buf[:pos].count(b"\n") + 1,
                              "the PGM header ends early: expected width, height and maxval")
        if not tok.group(1).isdigit():
            raise FormatError(p, buf[:start].count(b"\n") + 1,
                              f"PGM header field {len(fields) + 2} must be a positive integer; got {tok.group(1)[:20]!r}")
        fields.append(int(tok.group(1)))
        if len(fields) == 3:
            break
    w, h, maxval = fields
    if w <= 0 or h <= 0 or not 0 < maxval <= _MAX_GREY_16:
        raise FormatError(p, None, f"PGM header: width {w}, height {h}, maxval {maxval}; need width, height >= 1 and "
                                   f"1 <= maxval <= {_MAX_GREY_16}")
    return magic, w, h, maxval, pos


def _check_binary_raster(p: Path, buf: bytes, w: int, h: int, maxval: int, pos: int) -> None:
    """A P5 raster's size and values against its header (Pillow ignores extra bytes and clips large values)."""
    pos += 1  # exactly one whitespace byte before the raster
    dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
    need = w * h * dtype.itemsize
    raster = buf[pos:pos + need]
    if len(raster) < need:
        raise FormatError(p, None, f"the header says {w} x {h} pixels ({need} bytes), but the file holds only "
                                   f"{len(raster)} bytes of pixel data (truncated?)")
    if len(buf) - pos > need + 1 and buf[pos + need:].strip():
        raise FormatError(p, None, f"the header says {w} x {h} pixels, but {len(buf) - pos - need} bytes follow "
                                   "the pixel data (header and data disagree)")
    top = int(np.frombuffer(raster, dtype=dtype).max(initial=0))
    if top > maxval:
        raise FormatError(p, None, f"a pixel value {top} exceeds the header's maxval {maxval}")


def _plain_count_error(p: Path, buf: bytes, w: int, h: int, pos: int) -> FormatError | None:
    toks = re.sub(rb"#[^\n]*", b"", buf[pos:]).split()
    if len(toks) != w * h:
        return FormatError(p, None, f"the header says {w} x {h} = {w * h} pixels; the file holds {len(toks)} values")
    return None


def read_pgm(path: PathLike) -> NDArray:
    """Read a binary (P5) or plain (P2) PGM image into a 2-D array, first row = top, scaled by its maxval.

    Pillow decodes the pixels and scales them by the header's own maximum value
    to the full range of the result: ``uint8`` (0-255) for a maxval up to 255,
    ``uint16`` (0-65535) above it -- as ``map_server`` does (ROS 1 through
    SDL_image, nav2 through GraphicsMagick), so that a map written with maxval
    100 reads its 100 as white, not as grey. Pillow rounds ``v * 255 / maxval``
    to whole numbers: a value's occupancy moves by at most 0.5/255.

    Raises :class:`FormatError` for a bad magic number, a malformed header, or
    pixel data that disagrees with the header's size or maxval.

    Examples
    --------
    >>> p = tmp_dir() / "a.pgm"
    >>> _ = p.write_bytes(b"P5\\n# made by hand\\n3 2\\n255\\n" + bytes([0, 128, 255, 254, 205, 1]))
    >>> read_pgm(p)
    array([[  0, 128, 255],
           [254, 205,   1]], dtype=uint8)
    >>> _ = p.write_bytes(b"P2\\n3 1\\n100\\n100 0 80\\n")   # maxval 100: 100 is white
    >>> read_pgm(p)
    array([[255,   0, 204]], dtype=uint8)
    """
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, None, "no such file")
    buf = p.read_bytes()
    if not buf:
        raise FormatError(p, None, "the file is empty")
    magic, w, h, maxval, pos = _pgm_header(p, buf)
    if magic == b"P5":
        _check_binary_raster(p, buf, w, h, maxval, pos)
    elif (count := _plain_count_error(p, buf, w, h, pos)) is not None:
        raise count
    from PIL import Image

    try:
        with Image.open(_io.BytesIO(buf), formats=["PPM"]) as im:
            im.load()
            img = np.asarray(im)
    except (ValueError, OSError, SyntaxError) as exc:  # plain PGM: a value above maxval, or not a number
        text = str(exc)
        big = re.search(r"too large for this mode: (\d+)", text)
        if big:
            raise FormatError(p, None, f"a pixel value {big.group(1)} exceeds the header's maxval {maxval}") from None
        raise FormatError(p, None, f"plain PGM pixel values must be integers from 0 to maxval ({text})") from None
    return img.astype(np.uint16 if maxval > 255 else np.uint8)


def write_pgm(path: PathLike, image: NDArray) -> Path:
    """Write a 2-D uint8 array as a binary (P5) PGM, first row at the top.

    Examples
    --------
    >>> img = np.array([[0, 254], [205, 100]], dtype=np.uint8)
    >>> p = write_pgm(tmp_dir() / "m.pgm", img)
    >>> np.array_equal(read_pgm(p), img)
    True
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise ValueError(f"image must be a 2-D uint8 array; got shape {img.shape} and dtype {img.dtype}")
    out = Path(path)
    out.write_bytes(f"P5\n{img.shape[1]} {img.shape[0]}\n255\n".encode() + img.tobytes())
    return out


# ----------------------------------------------------------------------------- YAML
def parse_map_yaml(path: PathLike) -> dict:
    """Parse the flat ``key: value`` YAML of a ``map_server`` map (PyYAML); values keep their line numbers.

    Returns ``{key: (value, line)}``. A nested value, a key given twice or a
    YAML syntax error is a :class:`FormatError` naming the line. Numbers
    written as ``1e-2`` are numbers (as for ``map_server``'s yaml-cpp).

    Examples
    --------
    >>> p = tmp_text("m.yaml", "image: m.pgm  # the picture\\nresolution: 0.05\\norigin: [-1.0, 2, 0.0]\\n")
    >>> d = parse_map_yaml(p)
    >>> d["image"], d["resolution"], d["origin"]
    (('m.pgm', 1), (0.05, 2), ([-1.0, 2, 0.0], 3))
    """
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, None, "no such file")
    text = p.read_text(errors="replace")
    if not text.strip():
        raise FormatError(p, None, "the file is empty; expected a map_server YAML (image, resolution, origin, ...)")
    return load_yaml_mapping(p, text, "a map_server map description")


# ----------------------------------------------------------------------------- conversion
def image_to_occupancy(
    image: NDArray,
    mode: str = "trinary",
    negate: bool = False,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
    not_free: str = "unknown",
) -> NDArray[np.float64]:
    """Convert ``map_server`` image values to occupancy probabilities (NaN unknown), first row = top.

    ``image`` is ``(H, W)`` grey or ``(H, W, C)`` colour (with an alpha channel
    when ``C`` is 2 or 4). The rules are those of ``map_server`` (see the module
    docstring); ``not_free="occupied"`` turns every known-not-free and unknown
    cell into an obstacle (for maps whose walls are painted grey).

    Examples
    --------
    >>> img = np.array([[254, 205, 0, 150]], dtype=np.uint8)   # free, unknown, wall, grey wall
    >>> image_to_occupancy(img)
    array([[ 0., nan,  1., nan]])
    >>> image_to_occupancy(img, occupied_thresh=0.4)            # lower threshold: grey walls count
    array([[ 0., nan,  1.,  1.]])
    >>> image_to_occupancy(img, not_free="occupied")
    array([[0., 1., 1., 1.]])
    >>> image_to_occupancy(img, mode="scale").round(3)
    array([[0.   , 0.   , 1.   , 0.475]])
    """
    if mode not in _MODES:
        raise ValueError(f"mode must be one of {_MODES}; got {mode!r}")
    if not_free not in ("unknown", "occupied"):
        raise ValueError(f"not_free must be 'unknown' (map_server semantics) or 'occupied'; got {not_free!r}")
    if not (0.0 <= free_thresh < occupied_thresh <= 1.0):
        raise ValueError(f"need 0 <= free_thresh < occupied_thresh <= 1; got free_thresh={free_thresh}, "
                         f"occupied_thresh={occupied_thresh}")
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must be (H, W) or (H, W, C); got shape {img.shape}")
    full = float(_MAX_GREY_16) if img.dtype == np.uint16 else 255.0
    alpha = None
    if img.ndim == 3:
        c = img.shape[2]
        if c in (2, 4):
            alpha = img[..., -1].astype(float)
            img = img[..., :-1]
        v = img.astype(float).mean(axis=2)
    else:
        v = img.astype(float)
    if negate:
        v = full - v
    if mode == "raw":
        pct = v * (255.0 / full) if full != 255.0 else v
        occ = np.where(pct <= 100.0, pct / 100.0, np.nan)
    else:
        p = (full - v) / full
        occ = np.full(p.shape, np.nan)
        occ[p > occupied_thresh] = 1.0
        occ[p < free_thresh] = 0.0
        if mode == "scale":
            mid = (p >= free_thresh) & (p <= occupied_thresh)
            if alpha is not None:
                mid &= alpha > 0
            occ[mid] = (p[mid] - free_thresh) / (occupied_thresh - free_thresh)
    if not_free == "occupied":
        occ = np.where(occ == 0.0, 0.0, 1.0)
    return occ


def read_ros_map(
    path: PathLike,
    mode: str | None = None,
    negate: bool | None = None,
    occupied_thresh: float | None = None,
    free_thresh: float | None = None,
    not_free: str = "unknown",
) -> OccupancyGrid:
    """Read a ROS ``map_server`` map (YAML + PGM/PNG) into an :class:`~localize.OccupancyGrid`.

    Parameters
    ----------
    path : str or path-like
        The YAML file; its ``image`` is found relative to it.
    mode, negate, occupied_thresh, free_thresh : optional
        Override the YAML's values (the YAML's, or ``map_server``'s defaults
        trinary / 0 / 0.65 / 0.196, are used otherwise).
    not_free : {"unknown", "occupied"}
        ``"occupied"`` makes every cell that is not free an obstacle — the
        simple fix for maps with grey walls (see the module docstring).

    Returns
    -------
    OccupancyGrid
        Rows flipped so that row 0 is the bottom (smallest y), origin from the
        YAML. A non-zero origin yaw is ignored with a warning, as most ROS
        nodes do.

    Raises
    ------
    FormatError
        ``file:line: ...`` for a missing key, a bad value, a missing image or an
        image that disagrees with its header.

    Examples
    --------
    >>> d = tmp_dir()
    >>> _ = write_pgm(d / "m.pgm", np.array([[0, 0, 0], [254, 205, 150]], dtype=np.uint8))
    >>> _ = (d / "m.yaml").write_text("image: m.pgm\\nresolution: 0.5\\norigin: [-1.0, 2.0, 0.0]\\n"
    ...                               "negate: 0\\noccupied_thresh: 0.65\\nfree_thresh: 0.196\\n")
    >>> g = read_ros_map(d / "m.yaml")
    >>> g.data                      # image row 0 (the wall) is now the top row
    array([[ 0., nan, nan],
           [ 1.,  1.,  1.]])
    >>> g.origin, g.resolution
    (array([-1.,  2.]), 0.5)
    >>> read_ros_map(d / "m.yaml", not_free="occupied").data[0]
    array([0., 1., 1.])
    """
    p = Path(path)
    if p.suffix.lower() in (".pgm", ".png") or (p.is_file() and p.read_bytes()[:2] in (b"P5", b"P2", b"\x89P")):
        cand = p.with_suffix(".yaml")
        hint = f" (there is one: {cand})" if cand.exists() else ""
        raise FormatError(p, None, "this is the map's image; give the YAML file that describes it "
                                   f"(resolution, origin, thresholds){hint}")
    y = parse_map_yaml(p)
    for key in ("image", "resolution", "origin"):
        if key not in y:
            raise FormatError(p, None, f"missing key {key!r}: a map_server YAML needs image, resolution and origin")

    def num(key: str, default, lo: float, hi: float):
        if key not in y:
            return default
        v, ln = y[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or not lo <= v <= hi:
            raise FormatError(p, ln, f"{key} must be a number in [{lo:g}, {hi:g}]; got {v!r}")
        return float(v)

    res = num("resolution", None, 1e-9, 1e9)
    org, ln = y["origin"]
    if (not isinstance(org, list) or len(org) != 3
            or not all(isinstance(v, (int, float)) and np.isfinite(v) for v in org)):
        raise FormatError(p, ln, f"origin must be [x, y, yaw] (three numbers); got {org!r}")
    if abs(org[2]) > 1e-12:
        warnings.warn(f"{p}:{ln}: origin yaw {org[2]:g} rad is ignored (as map_server's users do); "
                      "the map is taken as axis-aligned", ParseWarning, stacklevel=2)
    y_mode = y.get("mode", ("trinary", 0))
    if y_mode[0] not in _MODES:
        raise FormatError(p, y_mode[1], f"mode must be one of {', '.join(_MODES)}; got {y_mode[0]!r}")
    y_neg = num("negate", 0, 0, 1)
    if y_neg not in (0.0, 1.0):
        raise FormatError(p, y["negate"][1], f"negate must be 0 or 1; got {y['negate'][0]!r}")
    occ_t = num("occupied_thresh", 0.65, 0, 1)
    free_t = num("free_thresh", 0.196, 0, 1)
    if occupied_thresh is not None:
        occ_t = float(occupied_thresh)
    if free_thresh is not None:
        free_t = float(free_thresh)
    if not free_t < occ_t:
        line = y["free_thresh"][1] if "free_thresh" in y else None
        raise FormatError(p, line, f"free_thresh ({free_t:g}) must be below occupied_thresh ({occ_t:g})")
    img_name, img_line = y["image"]
    img_path = (p.parent / str(img_name)) if not Path(str(img_name)).is_absolute() else Path(str(img_name))
    if not img_path.is_file():
        raise FormatError(p, img_line, f"the image {str(img_name)!r} does not exist (looked for {img_path})")
    img = _read_image(img_path)
    occ = image_to_occupancy(img, mode=mode or y_mode[0], negate=bool(y_neg if negate is None else negate),
                             occupied_thresh=occ_t, free_thresh=free_t, not_free=not_free)
    return OccupancyGrid(occ[::-1], res, origin=(float(org[0]), float(org[1])))


def _read_image(path: Path) -> NDArray:
    head = path.read_bytes()[:8]
    if head[:2] in (b"P5", b"P2"):
        return read_pgm(path)
    try:
        from PIL import Image
    except ImportError as exc:  # pragma: no cover - pillow is a dependency
        raise ImportError("reading PNG maps needs Pillow (pip install pillow)") from exc
    try:
        with Image.open(path) as im:
            im.load()
            if im.mode in ("P", "PA"):
                im = im.convert("RGBA")
            arr = np.array(im)
    except Exception as exc:  # Pillow reports damage as OSError, SyntaxError, zlib.error, struct.error ...
        raise FormatError(path, None, f"cannot read the image: damaged or not a PNG/PGM ({exc})") from None
    if arr.dtype == bool:
        arr = np.where(arr, 255, 0).astype(np.uint8)
    elif arr.dtype not in (np.uint8, np.uint16):
        if np.issubdtype(arr.dtype, np.integer) and arr.min() >= 0 and arr.max() <= _MAX_GREY_16:
            arr = arr.astype(np.uint16)
        else:
            raise FormatError(path, None, f"unsupported image pixel type {arr.dtype} (use 8- or 16-bit grey or RGB)")
    return arr


def write_ros_map(
    path: PathLike,
    grid: OccupancyGrid,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
) -> Path:
    """Write an :class:`~localize.OccupancyGrid` as a ``map_server`` map (YAML + trinary PGM).

    Like ``map_saver``: cells with occupancy ``>= occupied_thresh`` become 0
    (black), ``<= free_thresh`` 254 (white), everything else and unknown 205.
    The PGM is written beside the YAML with the same stem. Returns the YAML path.

    Examples
    --------
    >>> g = OccupancyGrid(np.array([[0.0, 1.0], [np.nan, 0.05]]), 0.1, origin=(2.0, -1.0))
    >>> p = write_ros_map(tmp_dir() / "out.yaml", g)
    >>> back = read_ros_map(p)
    >>> np.array_equal(back.data, g.data.round(), equal_nan=True), back.origin.tolist()
    (True, [2.0, -1.0])
    """
    check_grid(grid)
    if not (0.0 <= free_thresh < occupied_thresh <= 1.0):
        raise ValueError("need 0 <= free_thresh < occupied_thresh <= 1")
    yaml_path = Path(path)
    if yaml_path.suffix.lower() not in (".yaml", ".yml"):
        raise ValueError(f"path must end in .yaml or .yml; got {yaml_path.name}")
    d = grid.data
    img = np.full(d.shape, 205, dtype=np.uint8)
    with np.errstate(invalid="ignore"):
        img[d >= occupied_thresh] = 0
        img[d <= free_thresh] = 254
    pgm = yaml_path.with_suffix(".pgm")
    write_pgm(pgm, img[::-1].copy())
    yaml_path.write_text(
        f"image: {pgm.name}\nresolution: {grid.resolution:.6f}\n"
        f"origin: [{grid.origin[0]:.6f}, {grid.origin[1]:.6f}, 0.000000]\n"
        f"negate: 0\noccupied_thresh: {occupied_thresh}\nfree_thresh: {free_thresh}\nmode: trinary\n")
    return yaml_path
