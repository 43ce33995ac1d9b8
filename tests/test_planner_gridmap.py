"""The occupancy grid: loading, exact segment checks (corners), inflation, clearance."""

import math

import matplotlib.image as mpimg
import numpy as np
import pytest

from planner.gridmap import MapError, OccupancyGrid


def test_npy_and_png_orientation(tmp_path):
    occ = np.zeros((4, 6), bool)
    occ[0, 5] = True  # row 0 = y in [0, res): the south-east corner
    np.save(tmp_path / "m.npy", occ)
    g = OccupancyGrid.load(tmp_path / "m.npy", 2.0)
    assert (g.width, g.height) == (12.0, 8.0)
    assert not g.is_free(11.0, 1.0) and g.is_free(1.0, 1.0)
    img = np.ones((4, 6, 3))
    img[3, 5] = 0.0  # bottom image row = smallest y (north-up drawing)
    mpimg.imsave(tmp_path / "m.png", img)
    gp = OccupancyGrid.load(tmp_path / "m.png", 2.0)
    assert np.array_equal(gp.occ, occ)


def _matplotlib_reading(path) -> np.ndarray:
    """What the loader gave when it read PNGs with matplotlib: the mean of the colour channels < 0.5."""
    img = np.asarray(mpimg.imread(path), dtype=np.float64)
    if img.ndim == 3:
        img = img[..., :3].mean(axis=2) if img.shape[2] >= 3 else img[..., 0]
    return np.flipud(img < 0.5)


@pytest.mark.parametrize("mode", ["1", "L", "LA", "P", "RGB", "RGBA", "I;16"])
def test_png_of_every_kind_reads_as_matplotlib_read_it(tmp_path, mode):
    """PNG maps are decoded with Pillow (matplotlib.image alone took 0.2-0.5 s of `hil plan`'s wait); every
    PNG kind an editor writes gives the same grid as before, grey levels near the threshold included."""
    from PIL import Image

    rng = np.random.default_rng(len(mode))
    grey = rng.integers(0, 256, size=(37, 53)).astype(np.uint8)
    grey[:, :8] = np.arange(120, 136, 2, dtype=np.uint8)     # levels around 127.5, the threshold
    if mode == "I;16":
        img = Image.fromarray(grey.astype(np.uint16) * 257)
    elif mode in ("RGB", "RGBA"):
        rgb = np.stack([grey, np.roll(grey, 1, axis=1), np.roll(grey, 2, axis=0)], axis=2)
        img = Image.fromarray(rgb).convert(mode)
    else:
        img = Image.fromarray(grey).convert(mode)
    path = tmp_path / f"map_{mode.replace(';', '_')}.png"
    img.save(path)
    got = OccupancyGrid.load(path, 0.5).occ
    assert np.array_equal(got, _matplotlib_reading(path))
    assert got.any() and not got.all()


def test_loading_a_png_map_does_not_import_matplotlib(tmp_path):
    import subprocess
    import sys

    mpimg.imsave(tmp_path / "m.png", np.ones((4, 6, 3)))
    code = ("import sys; from planner.gridmap import OccupancyGrid; OccupancyGrid.load(sys.argv[1], 1.0); "
            "assert 'matplotlib' not in sys.modules, 'matplotlib imported'")
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "m.png")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_bad_maps(tmp_path):
    with pytest.raises(MapError, match="no such map"):
        OccupancyGrid.load(tmp_path / "missing.npy", 1.0)
    np.save(tmp_path / "f.npy", np.full((3, 3), 0.5))
    with pytest.raises(MapError, match="boolean"):
        OccupancyGrid.load(tmp_path / "f.npy", 1.0)
    np.save(tmp_path / "v.npy", np.zeros(5, bool))
    with pytest.raises(MapError, match="2-D"):
        OccupancyGrid.load(tmp_path / "v.npy", 1.0)
    (tmp_path / "m.txt").write_text("x")
    with pytest.raises(MapError, match="unsupported"):
        OccupancyGrid.load(tmp_path / "m.txt", 1.0)
    with pytest.raises(MapError, match="resolution"):
        OccupancyGrid(np.zeros((2, 2), bool), 0.0)


def test_diagonal_corner_cut_is_blocked():
    occ = np.zeros((10, 10), bool)
    occ[3, 4] = True
    occ[4, 3] = True  # two obstacle cells touching only at the corner (4, 4)
    g = OccupancyGrid(occ, 1.0)
    assert not g.segment_free(3.5, 3.5, 4.5, 4.5)   # through the shared corner
    assert not g.segment_free(1.0, 1.0, 7.0, 7.0)
    assert g.segment_free(3.5, 3.5, 3.5, 0.5)
    assert g.segment_free(5.5, 5.5, 8.5, 8.5)


def test_outside_is_occupied():
    g = OccupancyGrid(np.zeros((5, 5), bool), 1.0)
    assert not g.is_free(-0.1, 1.0) and not g.is_free(1.0, 5.0)
    assert not g.segment_free(1.0, 1.0, 6.0, 1.0)
    assert g.segment_free(0.0, 0.0, 4.99, 4.99)


def test_segment_free_agrees_with_dense_sampling():
    rng = np.random.default_rng(3)
    occ = rng.random((40, 40)) < 0.08
    g = OccupancyGrid(occ, 0.5)
    stricter = 0
    for _ in range(2000):
        x0, y0, x1, y1 = rng.uniform(0, 20, 4)
        t = np.linspace(0, 1, 4000)  # 5 mm spacing at most: far finer than half a cell
        sampled = all(g.is_free(x0 + s * (x1 - x0), y0 + s * (y1 - y0)) for s in t)
        exact = g.segment_free(x0, y0, x1, y1)
        if exact:
            assert sampled  # the exact check is never less strict than fine sampling
        elif sampled:
            stricter += 1  # grazing contacts finer than the sampling; must be rare
    assert stricter <= 20


def test_inflate_disc():
    occ = np.zeros((21, 21), bool)
    occ[10, 10] = True
    g = OccupancyGrid(occ, 0.5).inflate(1.0)
    # cell centres within 1 m (2 cells) of the obstacle centre (away from the inflated map edge)
    rr, cc = np.nonzero(g.occ[3:-3, 3:-3])
    rr, cc = rr + 3, cc + 3
    d = np.hypot(rr - 10, cc - 10) * 0.5
    assert d.max() <= 1.0 + 1e-9
    assert g.occ[10, 12] and g.occ[12, 10] and not g.occ[10, 13] and not g.occ[12, 12]


def test_map_edge_is_inflated_like_an_obstacle():
    g = OccupancyGrid(np.zeros((20, 30), bool), 0.5)
    for inflated in (g.inflate(1.0), g.inflate_velocity((0.0, 0.0), 1.0, 1.0)):
        occ = inflated.occ
        # the ring just outside the map is 0.5 m from the edge cells' centres: 1 m reaches 2 cells in
        assert occ[:2, :].all() and occ[-2:, :].all() and occ[:, :2].all() and occ[:, -2:].all()
        assert not occ[2:-2, 2:-2].any()
    assert not g.inflate(0.0).occ.any()


def test_inflate_velocity_grows_towards_the_approach_side():
    occ = np.zeros((41, 41), bool)
    occ[20, 20] = True
    g = OccupancyGrid(occ, 0.5)
    # vessel moving east (+x): it approaches the obstacle from the west side
    gi = g.inflate_velocity((2.0, 0.0), gain=1.0, base_radius=0.5)
    # count within 5 m of the obstacle (the map edge, 10 m away, is inflated too)
    west = sum(gi.occ[20, 20 - k] for k in range(1, 10))
    east = sum(gi.occ[20, 20 + k] for k in range(1, 10))
    north = sum(gi.occ[20 + k, 20] for k in range(1, 10))
    assert west == 5 and east == 1 and north == 1  # 0.5 + 1 s * 2 m/s = 2.5 m = 5 cells west
    assert np.array_equal(g.inflate_velocity((0.0, 0.0), 1.0, 0.5).occ, g.inflate(0.5).occ)


def test_clearance():
    occ = np.zeros((10, 10), bool)
    occ[0, :] = True
    c = OccupancyGrid(occ, 0.5).clearance()
    assert c[0, 3] == 0.0
    assert c[4, 3] == pytest.approx(2.0)
    assert math.isinf(OccupancyGrid(np.zeros((2, 2), bool), 1.0).clearance()[0, 0])


def test_polyline_free_is_every_segment_free():
    """The compiled polyline check against segment_free segment by segment: random grids and
    polylines (inside, crossing the edge, repeated points, one point, none)."""
    rng = np.random.default_rng(9)
    for _ in range(30):
        occ = rng.random((int(rng.integers(5, 60)), int(rng.integers(5, 60)))) < rng.choice([0.0, 0.01, 0.1])
        grid = OccupancyGrid(occ, float(rng.choice([0.25, 0.5, 1.0])))
        h, w = occ.shape[0] * grid.resolution, occ.shape[1] * grid.resolution
        for _ in range(40):
            n = int(rng.integers(0, 12))
            path = np.column_stack([rng.uniform(-1, w + 1, n), rng.uniform(-1, h + 1, n)])
            if n > 2:
                path[1] = path[0]
            want = all(grid.segment_free(*path[i], *path[i + 1]) for i in range(n - 1))
            assert grid.polyline_free(path) is want
            assert grid.path_free(path) is (grid.is_free(*path[0]) if n == 1 else want)


def test_marking_cells_drops_the_cached_free_regions():
    # A wall marked across the map after a search (a sensed obstacle) must part start and goal
    # for the next search: the connectivity labels cached by the first one are of the map before.
    from planner import make_planner
    from planner.params import PlannerParams
    from planner.problem import PlanningProblem
    from planner.termination import Termination

    g = OccupancyGrid(np.zeros((20, 20), bool), 1.0)
    problem = PlanningProblem(grid=g, start=(2.0, 10.0), goal=(18.0, 10.0))
    planner = make_planner("rrt-star", PlannerParams(seed=1))
    assert planner.solve(problem, Termination.iterations(2000)).status != "none"
    g.mark(np.array([[r, 10] for r in range(20)]))
    result = planner.solve(problem, Termination.iterations(2000))
    assert result.status == "none" and "different free regions" in result.reason
