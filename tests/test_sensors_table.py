"""The likelihood field's table built without scipy (issue 41: memory) against the table scipy built.

``LikelihoodField`` used to score every map cell from :attr:`OccupancyGrid.distance_field` (scipy's
Euclidean distance transform, a float64 field of the whole map, about 25 MB of working memory on an
800 x 800 map and 27 MB of scipy imports). It now fills its float32 table from squared cell distances
capped at ``max_dist``. The table must hold *the same bits* (every log-likelihood is a sum of its
entries, and the benchmark trajectories depend on every bit): ``scipy_table`` below is the old build,
verbatim, and the tests compare with ``np.array_equal``.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

import localize.sensors as sensors
from localize import OccupancyGrid
from localize.io import read_map
from localize.maps import benchmark_map, office, random_rooms
from localize.sensors import LikelihoodField


def scipy_table(lf: LikelihoodField) -> tuple[np.ndarray, float]:
    """``(table, unknown_log_prob)`` as ``LikelihoodField._build`` made them before issue 41's memory step."""
    g = lf.grid
    pad = int(math.ceil(lf.max_range / g.resolution)) + 2
    rows, cols = g.shape
    cells = lf.point_log_prob(g.distance_field)
    outside = float(lf.point_log_prob(lf.max_dist))
    u = outside
    if not g.unknown_is_obstacle and lf.unknown_neutral:
        known = ~g.unknown
        if known.any() and not known.all():
            u = float(np.log(np.mean(np.exp(cells[known]))))
            cells = np.where(known, cells, u)
    table = np.full((rows + 2 * pad, cols + 2 * pad), outside, dtype=np.float32)
    table[pad:pad + rows, pad:pad + cols] = cells
    return table, u


def with_unknown(g: OccupancyGrid, rng: np.random.Generator) -> OccupancyGrid:
    """``g`` with unknown margins and a few unknown blocks, unknown cells not obstacles."""
    d = np.array(g.data, dtype=float)
    h, w = d.shape
    d[:, : w // 15] = np.nan
    d[-(h // 12):, :] = np.nan
    for _ in range(4):
        i, j = rng.integers(0, h - 10), rng.integers(0, w - 10)
        d[i:i + rng.integers(3, 12), j:j + rng.integers(3, 12)] = np.nan
    return OccupancyGrid(d, g.resolution, origin=g.origin, unknown_is_obstacle=False)


def assert_same_table(lf: LikelihoodField) -> None:
    table, u = scipy_table(lf)
    assert lf.table.dtype == np.float32 and lf.table.shape == table.shape
    np.testing.assert_array_equal(lf.table, table)
    # the float64 mean score of the unknown cells may differ in its last bits (a tie between two nearest
    # obstacles gives sqrt((a r)^2 + (b r)^2) rounded either way), never in its float32 table entry
    assert lf.unknown_log_prob == pytest.approx(u, rel=1e-13, abs=0.0)


MAPS = {
    "office": lambda: office(),
    "office 5 cm": lambda: office(0.05),
    "rooms 3 cm": lambda: random_rooms((150, 230), 0.03, np.random.default_rng(1)),
    "rooms 25 cm": lambda: random_rooms((90, 70), 0.25, np.random.default_rng(2), n_boxes=9),
    "rooms 7 cm": lambda: random_rooms((200, 130), 0.07, np.random.default_rng(3), border=False),
    "benchmark 800": lambda: benchmark_map(800),
}
SETTINGS = {
    "defaults": dict(),
    "sharp": dict(sigma_hit=0.05),
    "wide": dict(sigma_hit=0.37, max_dist=2.0),
    "odd max_dist": dict(max_dist=0.333, z_hit=0.7, z_rand=0.3),
}


@pytest.mark.parametrize("kw", SETTINGS.values(), ids=SETTINGS.keys())
@pytest.mark.parametrize("make", MAPS.values(), ids=MAPS.keys())
def test_the_table_is_scipys_to_the_bit(make, kw):
    g = make()
    assert_same_table(LikelihoodField(g, 8.0, **kw))
    gu = with_unknown(g, np.random.default_rng(5))
    assert_same_table(LikelihoodField(gu, 8.0, **kw))                           # neutral unknown cells
    assert_same_table(LikelihoodField(gu, 8.0, unknown_neutral=False, **kw))    # scored by distance
    assert_same_table(LikelihoodField(gu, 8.0, unknown_is_obstacle=True, **kw))


def test_maps_without_obstacles_or_without_free_cells():
    empty = OccupancyGrid(np.zeros((40, 30)), 0.1)
    assert_same_table(LikelihoodField(empty, 5.0))
    assert np.all(LikelihoodField(empty, 5.0).table == np.float32(LikelihoodField(empty, 5.0).point_log_prob(0.8)))
    full = OccupancyGrid(np.ones((20, 25)), 0.1)
    assert_same_table(LikelihoodField(full, 5.0))
    one = np.zeros((1, 60))
    one[0, 17] = 1.0
    assert_same_table(LikelihoodField(OccupancyGrid(one, 0.05), 3.0))
    column = np.zeros((50, 1))
    column[[3, 40], 0] = 1.0
    assert_same_table(LikelihoodField(OccupancyGrid(column, 0.05), 3.0))


def test_a_cap_too_wide_takes_scipys_field_and_gives_the_same_table(monkeypatch):
    g = with_unknown(office(), np.random.default_rng(8))
    calls = []
    real = sensors.LikelihoodField._fill_capped

    def spy(self, inner, known):
        calls.append(real(self, inner, known))
        return calls[-1]

    monkeypatch.setattr(sensors.LikelihoodField, "_fill_capped", spy)
    md = 0.1 * (sensors._LF_MAX_CAP_CELLS + 1)
    wide = LikelihoodField(g, 8.0, max_dist=md)                                     # kc above the cap
    assert calls == [False] and "distance_field" in g.__dict__
    assert_same_table(wide)
    monkeypatch.setattr(sensors, "_LF_MAX_CAP_CELLS", 200)                          # the same through the passes
    g2 = with_unknown(office(), np.random.default_rng(8))
    np.testing.assert_array_equal(LikelihoodField(g2, 8.0, max_dist=md).table, wide.table)
    assert calls[-1] is True and "distance_field" not in g2.__dict__


def test_a_tie_that_rounds_apart_takes_scipys_field(monkeypatch):
    """If two ways of writing d^2 = a^2 + b^2 gave different float32 scores, scipy's choice would matter."""
    g = office(0.05)
    r, kc = g.resolution, int(math.ceil(0.8 / g.resolution)) + 1
    a, b = np.triu_indices(kc + 1)
    d2, dist = a * a + b * b, np.sqrt((a * r) ** 2 + (b * r) ** 2)
    split = [v for v in np.unique(d2[d2 <= kc * kc]) if np.unique(dist[d2 == v]).size > 1]
    assert split                                        # at 5 cm: 15^2 = 9^2 + 12^2, 0.75 and 0.75 + 1 ulp
    one = dist[d2 == split[0]].min()
    real = LikelihoodField.point_log_prob

    def last_bit_matters(self, d):                      # scores the two roundings of that tie apart
        v = np.asarray(real(self, d), dtype=float)
        return np.where(np.minimum(np.asarray(d, dtype=float), self.max_dist) == one, v + 1e-3, v)

    monkeypatch.setattr(LikelihoodField, "point_log_prob", last_bit_matters)
    lf = LikelihoodField(g, 8.0)
    assert "distance_field" in g.__dict__              # the table came from scipy's field ...
    np.testing.assert_array_equal(lf.table, scipy_table(lf)[0])
    monkeypatch.setattr(LikelihoodField, "point_log_prob", real)
    g2 = office(0.05)
    LikelihoodField(g2, 8.0)
    assert "distance_field" not in g2.__dict__          # ... which it does not need without such a tie


@pytest.mark.parametrize("cap", [0, 1, 2, 5, 16, 40])
def test_capped_squared_distances_are_exact_below_the_cap(cap):
    rng = np.random.default_rng(cap)
    obst = rng.random((70, 90)) < 0.01
    obst[40:44, 10:60] = True
    got = sensors._capped_sq_distance(obst, cap)
    assert got.dtype == np.int16
    _, (fi, fj) = distance_transform_edt(~obst, return_indices=True)
    rows, cols = np.indices(obst.shape)
    true = (fi - rows) ** 2 + (fj - cols) ** 2
    near = true <= cap * cap
    np.testing.assert_array_equal(got[near], true[near])
    assert np.all(got[~near] > cap * cap) and got.max() <= 2 * (cap + 1) ** 2
    with pytest.raises(ValueError, match="cap must be at most 126"):
        sensors._capped_sq_distance(obst, 127)


def test_the_willow_map_of_the_global_benchmark(shared_data):
    g = read_map(shared_data / "willow" / "willow-2010-02-18-0.10.yaml", occupied_thresh=0.2)
    g = OccupancyGrid(g.data, g.resolution, origin=g.origin, unknown_is_obstacle=False)
    for sigma in (0.2, 0.3):
        assert_same_table(LikelihoodField(g, 30.0, sigma_hit=sigma))


def test_a_likelihood_field_cycle_loads_neither_scipy_nor_matplotlib():
    """``import localize`` and one MCL cycle with a likelihood field import no scipy (27 MB) or matplotlib."""
    code = (
        "import sys, numpy as np, localize\n"
        "from localize.mcl import MCL\n"
        "from localize.motion import OdometryMotion\n"
        "from localize.sensors import LikelihoodField\n"
        "g = localize.maps.office()\n"
        "lf = LikelihoodField(g, 8.0, unknown_is_obstacle=False)\n"
        "rng = np.random.default_rng(0)\n"
        "f = MCL(g.sample_free(500, rng), OdometryMotion((0.02, 0.0005, 0.02, 0.0005)), lf, rng=rng)\n"
        "f.predict((np.zeros(3), np.array([0.1, 0.0, 0.05])))\n"
        "f.update(np.full(30, 2.0), np.linspace(-1.5, 1.5, 30))\n"
        "f.resample()\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'scipy', 'matplotlib'}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
