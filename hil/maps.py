"""Seeded generators of the occupancy maps in ``configs/maps/`` (rebuild with ``python -m hil.maps``).

Map frame (see planner/gridmap.py): ``occ[row, col]``, row 0 at y = 0 (south), col 0 at x = 0
(west), x east and y north in metres, ``True`` = obstacle. Every map is a function of its seed
only, so the committed ``.npy`` files can be regenerated bit for bit.

* ``harbour``    200 m x 150 m at 0.5 m/cell: quay, three piers, a breakwater with an entrance,
  moored boats (section 4.2, Figure 9).
* ``labyrinth``  100 m x 100 m at 0.5 m/cell: labyrinth walls, a bug trap and irregular islands
  (section 4.2, Figure 10).
* ``bench_discs`` / ``bench_bugtrap`` / ``bench_maze``  100 m x 100 m at 0.5 m/cell: the three
  maps of ``hil bench planner`` (sparse discs, one bug trap, a maze with narrow doors).
* :func:`random_map` the Figure 11 generator (random discs and rectangles), used per Monte Carlo run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

MAP_DIR = Path(__file__).resolve().parent.parent / "configs" / "maps"
RESOLUTION = 0.5  # m per cell for every committed map
MAX_MAP_CELLS = 64_000_000  # 8000 x 8000 cells (4 km square at 0.5 m): 64 MB as bool; larger is refused


def check_npy_header(path: Path, max_cells: int = MAX_MAP_CELLS) -> None:
    """Refuse, before anything is allocated, a ``.npy`` map whose header claims more than
    ``max_cells`` cells or more bytes than the file holds (ValueError with a one-line reason)."""
    from numpy.lib import format as npf

    with open(path, "rb") as fh:
        try:
            version = npf.read_magic(fh)
            read = npf.read_array_header_1_0 if version == (1, 0) else npf.read_array_header_2_0
            shape, _fortran, dtype = read(fh)
        except (ValueError, SyntaxError, EOFError) as exc:
            raise ValueError(f"not a .npy array ({exc})") from None
        offset = fh.tell()
    if dtype.hasobject:
        raise ValueError("a .npy of Python objects is not a map")
    cells = 1
    for n in shape:
        cells *= int(n)
    if cells > max_cells:
        dims = " x ".join(str(int(n)) for n in shape)
        raise ValueError(f"header claims {dims} = {cells} cells, more than the {max_cells} a map may have")
    size = path.stat().st_size - offset
    if cells * dtype.itemsize > size:
        raise ValueError(f"header claims {cells * dtype.itemsize} bytes of data, the file holds {size}")


class Canvas:
    """An occupancy grid being drawn in metric coordinates (x east, y north)."""

    def __init__(self, width: float, height: float, resolution: float = RESOLUTION) -> None:
        self.resolution = resolution
        self.occ = np.zeros((int(round(height / resolution)), int(round(width / resolution))), dtype=bool)
        rows, cols = self.occ.shape
        # Cell-centre coordinates (m).
        self.xc = (np.arange(cols) + 0.5) * resolution
        self.yc = (np.arange(rows) + 0.5) * resolution

    def rect(self, x0: float, x1: float, y0: float, y1: float) -> None:
        """Fill the axis-aligned rectangle [x0, x1] x [y0, y1] (m), cell centres inside."""
        cx = (self.xc >= min(x0, x1)) & (self.xc <= max(x0, x1))
        cy = (self.yc >= min(y0, y1)) & (self.yc <= max(y0, y1))
        self.occ[np.ix_(cy, cx)] = True

    def disc(self, x: float, y: float, radius: float) -> None:
        """Fill a disc of ``radius`` m centred at (x, y)."""
        dx = self.xc[None, :] - x
        dy = self.yc[:, None] - y
        self.occ |= dx * dx + dy * dy <= radius * radius

    def rotated_rect(self, x: float, y: float, length: float, width: float, angle: float) -> None:
        """Fill a rectangle centred at (x, y), ``length`` along ``angle`` (rad from +x), ``width`` across."""
        dx = self.xc[None, :] - x
        dy = self.yc[:, None] - y
        c, s = np.cos(angle), np.sin(angle)
        along = dx * c + dy * s
        across = -dx * s + dy * c
        self.occ |= (np.abs(along) <= length / 2) & (np.abs(across) <= width / 2)

    def blob(self, x: float, y: float, radius: float, rng: np.random.Generator, lobes: int = 5) -> None:
        """Fill an irregular island: a disc whose radius varies with a few random harmonics."""
        dx = self.xc[None, :] - x
        dy = self.yc[:, None] - y
        ang = np.arctan2(dy, dx)
        r = np.full_like(ang, radius)
        for k in range(2, 2 + lobes):
            r += radius * rng.uniform(0.0, 0.18) * np.cos(k * ang + rng.uniform(0, 2 * np.pi))
        self.occ |= np.hypot(dx, dy) <= r

    def clear_disc(self, x: float, y: float, radius: float) -> None:
        """Make a disc free again (keeps start and goal areas open)."""
        dx = self.xc[None, :] - x
        dy = self.yc[:, None] - y
        self.occ &= ~(dx * dx + dy * dy <= radius * radius)


def harbour() -> np.ndarray:
    """Figure 9 style harbour, 200 m x 150 m: quay along the south, three piers, moored boats and
    a breakwater with its entrance in the north-east."""
    c = Canvas(200.0, 150.0)
    c.rect(0, 200, 0, 12)                      # quay / land along the south edge
    c.rect(0, 8, 0, 60)                        # land on the west side
    for x0, top in ((40, 68), (95, 78), (145, 58)):
        c.rect(x0, x0 + 6, 12, top)            # piers, 6 m wide
    # Moored boats (2.5 m x 8 m) alongside the piers, a few rotated boats at anchor.
    for x0, ys in ((40, (20, 34, 50)), (95, (22, 40, 60)), (145, (20, 38))):
        for y in ys:
            c.rect(x0 - 3.5, x0 - 1.0, y, y + 8)
            c.rect(x0 + 7.0, x0 + 9.5, y + 4, y + 12)
    for x, y, a in ((70, 92, 0.4), (125, 96, -0.6), (30, 88, 1.2)):
        c.rotated_rect(x, y, 9.0, 3.0, a)
    c.rect(0, 150, 108, 113)                   # breakwater, 5 m wide, entrance to its east
    c.rect(150, 200, 120, 123)                 # outer mole overlapping the entrance
    c.disc(178, 92, 5.0)                       # a rock inside
    return c.occ


def labyrinth(seed: int = 7) -> np.ndarray:
    """Figure 10 style environment, 100 m x 100 m: labyrinth walls with passages, a bug trap and
    irregular (partly concave) islands."""
    rng = np.random.default_rng(seed)
    c = Canvas(100.0, 100.0)
    c.rect(0, 64, 27, 29)                      # wall A, passage at its east end
    c.rect(36, 100, 66, 68)                    # wall B, passage at its west end
    c.rect(80, 82, 29, 52)                     # spur hanging from the east, a dead end
    # Bug trap: a U open to the south-east corner of the middle corridor.
    c.rect(36, 58, 54, 56)                     # top
    c.rect(36, 38, 38, 56)                     # west arm
    c.rect(56, 58, 44, 56)                     # east arm, shorter
    c.rect(36, 48, 38, 40)                     # bottom, open between x = 48 and 56
    for x, y, r in ((20, 12, 4.0), (46, 16, 3.5), (72, 44, 3.0), (20, 45, 5.0), (64, 82, 4.5), (82, 84, 3.0),
                    (40, 86, 3.5), (12, 78, 3.0)):
        c.blob(x, y, r, rng)
    c.clear_disc(8, 8, 5)
    c.clear_disc(92, 92, 5)
    return c.occ


def bench_discs(seed: int = 11) -> np.ndarray:
    """Sparse discs: 14 discs of radius 3-7 m scattered over 100 m x 100 m."""
    rng = np.random.default_rng(seed)
    c = Canvas(100.0, 100.0)
    for _ in range(14):
        c.disc(rng.uniform(15, 85), rng.uniform(15, 85), rng.uniform(3, 7))
    c.clear_disc(5, 5, 4)
    c.clear_disc(95, 95, 4)
    return c.occ


def bench_bugtrap() -> np.ndarray:
    """One bug trap (a deep U, 2 m walls) opening towards the start in the south-west."""
    c = Canvas(100.0, 100.0)
    c.rect(30, 72, 70, 72)                     # closed top (towards the goal)
    c.rect(70, 72, 30, 72)                     # closed east side
    c.rect(30, 32, 40, 72)                     # west arm
    c.rect(40, 72, 30, 32)                     # south arm; opening at the south-west corner
    return c.occ


def bench_maze() -> np.ndarray:
    """A maze of five walls, each with one narrow door (2.5 m) at alternating ends."""
    c = Canvas(100.0, 100.0)
    door = 2.5
    for i, y in enumerate((18, 34, 50, 66, 82)):
        dx = 10 + 20 * i                        # doors move east, forcing a zigzag
        c.rect(0, dx, y, y + 1.5)
        c.rect(dx + door, 100, y, y + 1.5)
    return c.occ


def open_water() -> np.ndarray:
    """Figure 12's encounters: 200 m x 120 m of open water (the map edge is the only obstacle)."""
    return Canvas(200.0, 120.0).occ


def random_map(rng: np.random.Generator, width: float = 100.0, height: float = 100.0,
               n_discs: tuple[int, int] = (6, 14), n_rects: tuple[int, int] = (2, 6),
               radius: tuple[float, float] = (2.0, 7.0), resolution: float = RESOLUTION) -> np.ndarray:
    """Figure 11 generator: a random number of discs and rotated rectangles (seeded ``rng``)."""
    c = Canvas(width, height, resolution)
    for _ in range(int(rng.integers(n_discs[0], n_discs[1] + 1))):
        c.disc(rng.uniform(0, width), rng.uniform(0, height), rng.uniform(*radius))
    for _ in range(int(rng.integers(n_rects[0], n_rects[1] + 1))):
        c.rotated_rect(rng.uniform(0, width), rng.uniform(0, height), rng.uniform(6, 25), rng.uniform(1.5, 4),
                       rng.uniform(0, np.pi))
    return c.occ


MAPS = {
    "harbour": harbour,
    "labyrinth": labyrinth,
    "open_water": open_water,
    "bench_discs": bench_discs,
    "bench_bugtrap": bench_bugtrap,
    "bench_maze": bench_maze,
}


def write_all(out_dir: Path = MAP_DIR) -> list[Path]:
    """(Re)generate every committed map as ``<name>.npy`` (bool) in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in MAPS.items():
        path = out_dir / f"{name}.npy"
        np.save(path, make())
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m hil.maps",
                                description="Regenerate configs/maps/*.npy from their seeds.")
    p.add_argument("--out", type=Path, default=MAP_DIR, help="output folder (default configs/maps)")
    args = p.parse_args(argv)
    for path in write_all(args.out):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
