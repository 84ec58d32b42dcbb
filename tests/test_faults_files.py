"""Map files and AMCL parameter files under faults (issue 39, findings 4 and 5).

PGM images are scaled by their own maxval, as map_server does (Pillow decodes
them); the map YAML and AMCL files are read with PyYAML, and a key given twice
is refused with its line, as ROS refuses it. Property tests draw PGM headers
(maxval 1-65535, plain and binary) and AMCL parameter files.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from localize import amcl, io
from localize.io import FormatError

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def pgm_bytes(values: np.ndarray, maxval: int, plain: bool) -> bytes:
    h, w = values.shape
    head = f"{'P2' if plain else 'P5'}\n# drawn by the test\n{w} {h}\n{maxval}\n".encode()
    if plain:
        return head + "\n".join(" ".join(str(int(v)) for v in row) for row in values).encode() + b"\n"
    return head + values.astype(">u2" if maxval > 255 else np.uint8).tobytes()


def ros_map(folder, pgm: bytes, extra: str = ""):
    (folder / "m.pgm").write_bytes(pgm)
    y = folder / "m.yaml"
    y.write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n" + extra)
    return y


# ------------------------------------------------------------------ finding 4: maxval
def test_the_issue_map_with_maxval_100_reads_as_free_occupied_unknown(tmp_path):
    y = ros_map(tmp_path, b"P5\n3 1\n100\n\x64\x00\x50")  # printf 'P5\n3 1\n100\n\x64\x00\x50'
    assert np.array_equal(io.read_ros_map(y).data, [[0.0, 1.0, np.nan]], equal_nan=True)


@pytest.mark.parametrize("plain", [False, True])
def test_a_12_bit_map_is_scaled_by_its_maxval_not_by_65535(tmp_path, plain):
    y = ros_map(tmp_path, pgm_bytes(np.array([[4095, 0, 2000]]), 4095, plain))
    assert np.array_equal(io.read_ros_map(y).data, [[0.0, 1.0, np.nan]], equal_nan=True)
    assert io.read_pgm(tmp_path / "m.pgm").tolist() == [[65535, 0, round(2000 * 65535 / 4095)]]


@pytest.mark.parametrize("plain", [False, True])
def test_a_pixel_above_maxval_is_named(tmp_path, plain):
    p = tmp_path / "m.pgm"
    p.write_bytes(pgm_bytes(np.array([[100, 0, 101]]), 100, plain))
    with pytest.raises(FormatError, match=r"m\.pgm: a pixel value 101 exceeds the header's maxval 100"):
        io.read_pgm(p)


@FAST
@given(maxval=st.integers(1, 65535), plain=st.booleans(), shape=st.tuples(st.integers(1, 4), st.integers(1, 5)),
       data=st.data())
def test_any_pgm_header_reads_scaled_by_its_maxval_as_map_server(tmp_path, maxval, plain, shape, data):
    v = np.array(data.draw(st.lists(st.integers(0, maxval), min_size=shape[0] * shape[1],
                                    max_size=shape[0] * shape[1]))).reshape(shape)
    y = ros_map(tmp_path, pgm_bytes(v, maxval, plain))
    img = io.read_pgm(tmp_path / "m.pgm")
    full = 255 if maxval <= 255 else 65535
    assert img.dtype == (np.uint8 if full == 255 else np.uint16) and img.shape == shape
    assert np.all(np.abs(img - v * full / maxval) <= 0.5)  # Pillow rounds v * full / maxval
    # map_server: p = (maxval - v) / maxval; > 0.65 occupied, < 0.196 free, else unknown
    p = (maxval - v) / maxval
    expected = np.where(p > 0.65, 1.0, np.where(p < 0.196, 0.0, np.nan))
    got = io.read_ros_map(y).data[::-1]
    clear = (np.abs(p - 0.65) > 1 / full) & (np.abs(p - 0.196) > 1 / full)  # away from a threshold's rounding
    assert np.array_equal(got[clear], expected[clear], equal_nan=True)


@FAST
@given(maxval=st.integers(1, 65534), plain=st.booleans(), excess=st.integers(1, 1000))
def test_any_pixel_above_any_maxval_is_an_error_naming_both(tmp_path, maxval, plain, excess):
    top = min(maxval + excess, 65535)
    p = tmp_path / "m.pgm"
    p.write_bytes(pgm_bytes(np.array([[0, top]]), maxval, plain) if top <= 255 or maxval > 255 or plain
                  else pgm_bytes(np.array([[0, top]]), 256, plain).replace(b"\n256\n", f"\n{maxval}\n".encode()))
    if not plain and maxval <= 255 < top:  # an 8-bit raster cannot hold it: the file is two bytes too long
        with pytest.raises(FormatError, match="header and data disagree|exceeds"):
            io.read_pgm(p)
        return
    with pytest.raises(FormatError, match=f"a pixel value {top} exceeds the header's maxval {maxval}"):
        io.read_pgm(p)


@pytest.mark.parametrize("header, message", [
    (b"P5\n3 1\n0\n\x00\x00\x00", "1 <= maxval <= 65535"),
    (b"P5\n3 1\n65536\n\x00\x00\x00", "1 <= maxval <= 65535"),
    (b"P2\n3 1\n-5\n0 0 0", "must be a positive integer"),
    (b"P2\n3\n", "the PGM header ends early"),
    (b"P2\n3 1\n9\n0 x 0", "must be integers from 0 to maxval"),
])
def test_bad_pgm_headers_keep_their_clear_errors(tmp_path, header, message):
    p = tmp_path / "m.pgm"
    p.write_bytes(header)
    with pytest.raises(FormatError, match=message):
        io.read_pgm(p)


# ------------------------------------------------------------------ the map YAML with PyYAML
def test_map_yaml_reads_yaml_as_yaml(tmp_path):
    img = np.array([[254, 0]], dtype=np.uint8)
    io.write_pgm(tmp_path / "m.pgm", img)
    y = tmp_path / "m.yaml"
    y.write_text("# a map\nimage: \"m.pgm\"\nresolution: 5e-2\norigin:\n  - -1.0\n  - 2\n  - 0\n")  # block list
    g = io.read_ros_map(y)
    assert g.resolution == 0.05 and g.origin.tolist() == [-1.0, 2.0]


@pytest.mark.parametrize("text, line, message", [
    ("image: m.pgm\nresolution: [0.05\norigin: [0, 0, 0]\n", 3, "not valid YAML"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nimage: m.pgm\n", 4, r"key 'image' appears twice \(first on line 1\)"),
    ("- image\n- m.pgm\n", 1, "expected 'key: value'"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh:\n", 4, "has no value"),
])
def test_map_yaml_errors_name_the_line(tmp_path, text, line, message):
    io.write_pgm(tmp_path / "m.pgm", np.zeros((1, 1), dtype=np.uint8))
    y = tmp_path / "m.yaml"
    y.write_text(text)
    with pytest.raises(FormatError, match=message) as e:
        io.read_ros_map(y)
    assert e.value.path == str(y) and e.value.line == line


# ------------------------------------------------------------------ finding 5: AMCL duplicate key
def test_an_amcl_file_with_a_key_given_twice_is_refused_with_file_and_line(tmp_path):
    p = tmp_path / "amcl.yaml"
    p.write_text("amcl:\n  ros__parameters:\n    max_particles: 2000\n    alpha1: 0.2\n    max_particles: 500\n")
    with pytest.raises(FormatError, match=r"amcl\.yaml:5: key 'max_particles' appears twice \(first on line 3\); "
                                          "ROS refuses such a file"):
        amcl.read_amcl_params(p)


# ------------------------------------------------------------------ AMCL files (hypothesis)
NUMBERS = st.floats(0.0, 2.0, allow_nan=False).map(lambda x: round(x, 4))


@st.composite
def amcl_files(draw):
    n_min = draw(st.integers(1, 3000))
    params = {
        "alpha1": draw(NUMBERS), "alpha2": draw(NUMBERS), "alpha3": draw(NUMBERS), "alpha4": draw(NUMBERS),
        "max_beams": draw(st.integers(1, 400)), "min_particles": n_min,
        "max_particles": draw(st.integers(n_min, 6000)),
        "laser_model_type": draw(st.sampled_from(["likelihood_field", "beam", "likelihood_field_prob"])),
        "sigma_hit": draw(st.floats(0.01, 1.0).map(lambda x: round(x, 4))),
        "update_min_d": draw(NUMBERS), "update_min_a": draw(NUMBERS),
        "resample_interval": draw(st.integers(1, 5)),
    }
    keys = draw(st.lists(st.sampled_from(sorted(params)), min_size=1, unique=True))
    return {k: params[k] for k in keys}, draw(st.booleans())


@FAST
@given(drawn=amcl_files(), duplicate=st.integers(-1, 20))
def test_any_amcl_file_maps_as_its_dict_or_names_the_repeated_key(tmp_path, drawn, duplicate):
    params, ros1_namespace = drawn
    doc = {"amcl": params} if ros1_namespace else {"amcl": {"ros__parameters": params}}
    text = yaml.safe_dump(doc, sort_keys=False)
    lines = text.splitlines()
    p = tmp_path / "amcl.yaml"
    param_lines = [i for i, s in enumerate(lines) if s.startswith("    " if not ros1_namespace else "  ")
                   and not s.strip().startswith("ros__parameters")]
    if 0 <= duplicate < len(param_lines):  # repeat one parameter line at the end: ROS refuses the file
        i = param_lines[duplicate]
        lines.append(lines[i])
        p.write_text("\n".join(lines) + "\n")
        key = lines[i].strip().split(":")[0]
        with pytest.raises(FormatError, match=f"key '{key}' appears twice \\(first on line {i + 1}\\)") as e:
            amcl.read_amcl_params(p)
        assert e.value.line == len(lines)
        return
    p.write_text(text)
    try:
        want = amcl.amcl_settings(params, nav2=not ros1_namespace or None)
    except FormatError as e:  # e.g. max_particles below the dialect's default min_particles: the file says the same
        with pytest.raises(FormatError) as from_file:
            amcl.read_amcl_params(p)
        assert from_file.value.reason == e.reason and from_file.value.path == str(p)
        key = e.reason.split()[0]
        if key in params:  # the line of the parameter that is wrong
            assert lines[from_file.value.line - 1].strip().startswith(f"{key}:")
        return
    m = amcl.read_amcl_params(p)
    assert m.settings.keys() == want.settings.keys()
    for k, v in want.settings.items():
        assert repr(m.settings[k]) == repr(v), k
    s, defaults = m.settings, (amcl.ROS1_DEFAULTS if m.dialect == "ros1" else amcl.NAV2_DEFAULTS)
    assert s["particles"] == params.get("max_particles", defaults["max_particles"])
    assert s["beams"] == params.get("max_beams", defaults["max_beams"])
    assert (s["kld"] is None) == (params.get("min_particles", defaults["min_particles"]) == s["particles"])
    assert s["sensor"] == ("beam" if params.get("laser_model_type", "likelihood_field") == "beam" else "likelihood")
    if m.dialect == "nav2":  # the differential model: PR variances as written
        assert all(math.isclose(a, params.get(f"alpha{i}", 0.2), abs_tol=1e-9)
                   for i, a in enumerate(s["alphas"], start=1))
