"""The binary occupancy map of the paper (section 4.2) in the map frame.

``occ[row, col]`` is True for an obstacle; row 0 is at y = 0 and column 0 at x = 0; cell
(r, c) covers x in [c res, (c+1) res), y in [r res, (r+1) res). Anything outside the map is
treated as an obstacle.
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path

import numpy as np
from scipy import ndimage

from planner import _kernels


class MapError(ValueError):
    """A map file or array that cannot be used (one-line message)."""


def _png_levels(p: Path) -> np.ndarray:
    """A PNG's samples scaled to [0, 1] (as matplotlib.image.imread gives them), decoded with Pillow
    alone: importing matplotlib.image took longer than a short planning deadline."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(p) as im:
            if im.format != "PNG":
                raise MapError(f"{p}: not a readable PNG: a {im.format} image")
            if im.mode.startswith("I;16"):
                return np.asarray(im, dtype=np.float64) / 65535.0
            rgba = im if im.mode in ("L", "RGB", "RGBA") else im.convert("RGBA")
            return np.asarray(rgba, dtype=np.float64) / 255.0
    except (UnidentifiedImageError, ValueError, OSError, SyntaxError) as exc:
        raise MapError(f"{p}: not a readable PNG: {exc}") from None


class OccupancyGrid:
    """Binary occupancy grid with exact segment checks and obstacle inflation."""

    def __init__(self, occ: np.ndarray, resolution: float) -> None:
        occ = np.asarray(occ)
        if occ.ndim != 2 or occ.shape[0] < 1 or occ.shape[1] < 1:
            raise MapError(f"map must be a 2-D grid, got shape {occ.shape}")
        if occ.dtype != bool:
            numeric = np.issubdtype(occ.dtype, np.integer) or np.issubdtype(occ.dtype, np.floating)
            if not numeric or not np.isin(occ, (0, 1)).all():
                raise MapError(f"map must be boolean (True = obstacle) or 0/1 numbers, got {occ.dtype}"
                               + ("" if not numeric else " holding other values"))
            occ = occ.astype(bool)
        if isinstance(resolution, bool) or not (isinstance(resolution, numbers.Real) and math.isfinite(resolution)
                                                and resolution > 0):
            raise MapError(f"map resolution must be a finite number > 0 m/cell, got {resolution!r}")
        self.occ: np.ndarray = np.ascontiguousarray(occ)
        self.resolution: float = float(resolution)
        self._u8: np.ndarray = self.occ.view(np.uint8)
        self._clearance: np.ndarray | None = None
        self._free_labels: np.ndarray | None = None  # cache of planner.core.free_regions

    @classmethod
    def load(cls, path: str | Path, resolution: float) -> OccupancyGrid:
        """Load a ``.npy`` (bool, True = obstacle, row 0 at y = 0) or a ``.png`` (white free,
        black obstacle, drawn north-up: the top image row is the largest y)."""
        p = Path(path)
        if not p.is_file():
            raise MapError(f"{p}: no such map file")
        suffix = p.suffix.lower()
        if suffix == ".npy":
            try:
                occ = np.load(p, allow_pickle=False)
            except (ValueError, OSError) as exc:
                raise MapError(f"{p}: not a readable .npy array: {exc}") from None
        elif suffix == ".png":
            img = _png_levels(p)
            if img.ndim == 3:
                img = img[..., :3].mean(axis=2) if img.shape[2] >= 3 else img[..., 0]
            occ = np.flipud(img < 0.5)
        else:
            raise MapError(f"{p}: unsupported map format {suffix or '(none)'} (use .npy or .png)")
        try:
            return cls(occ, resolution)
        except MapError as exc:
            raise MapError(f"{p}: {exc}") from None

    @property
    def rows(self) -> int:
        return self.occ.shape[0]

    @property
    def cols(self) -> int:
        return self.occ.shape[1]

    @property
    def width(self) -> float:
        """Extent along x (east), metres."""
        return self.cols * self.resolution

    @property
    def height(self) -> float:
        """Extent along y (north), metres."""
        return self.rows * self.resolution

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell containing (x, y)."""
        return int(math.floor(y / self.resolution)), int(math.floor(x / self.resolution))

    def contains(self, x: float, y: float) -> bool:
        return 0.0 <= x < self.width and 0.0 <= y < self.height

    def is_free(self, x: float, y: float) -> bool:
        """True if (x, y) is inside the map and in a free cell."""
        if not self.contains(x, y):
            return False
        r, c = self.cell_of(x, y)
        return not bool(self.occ[r, c])

    def segment_free(self, x0: float, y0: float, x1: float, y1: float) -> bool:
        """Exact cell traversal of the closed segment, corner touches included (see _kernels)."""
        return bool(_kernels.segment_free(self._u8, self.resolution, float(x0), float(y0), float(x1), float(y1)))

    def polyline_free(self, path: np.ndarray) -> bool:
        """Every segment of the polyline ``path`` (N, 2) :meth:`segment_free`, in one compiled call
        (True for fewer than two points)."""
        path = np.ascontiguousarray(path, dtype=np.float64).reshape(-1, 2)
        return bool(_kernels.polyline_free(self._u8, self.resolution, path))

    def path_free(self, path: np.ndarray) -> bool:
        """:meth:`polyline_free`, and a single point must be free."""
        path = np.asarray(path, dtype=np.float64)
        if len(path) == 1:
            return self.is_free(*path[0])
        return self.polyline_free(path)

    def _bordered(self) -> np.ndarray:
        """The grid with one ring of obstacle cells around it: the chart's edge is inflated like
        any obstacle (outside the map counts as occupied), so paths keep clear of it too."""
        return np.pad(self.occ, 1, constant_values=True)

    def inflate(self, radius: float) -> OccupancyGrid:
        """Disc dilation: a cell becomes an obstacle if its centre is within ``radius`` metres of
        the centre of an obstacle cell or of the ring of cells just outside the map."""
        if radius < 0:
            raise MapError("inflation radius must be >= 0")
        if radius == 0:
            return OccupancyGrid(self.occ.copy(), self.resolution)
        dist = ndimage.distance_transform_edt(~self._bordered()) * self.resolution
        return OccupancyGrid(dist[1:-1, 1:-1] <= radius + 1e-12, self.resolution)

    def inflate_velocity(self, velocity: tuple[float, float], gain: float, base_radius: float) -> OccupancyGrid:
        """Section 3.3: inflate by ``base_radius`` plus ``gain`` times the velocity component
        towards the obstacle. A free cell c becomes an obstacle if some obstacle cell o satisfies
        |o - c| <= base_radius + gain * max(0, v . (o - c) / |o - c|) (centre distances): the
        obstacle grows towards the side the vessel approaches it from."""
        vx, vy = float(velocity[0]), float(velocity[1])
        if gain < 0 or base_radius < 0:
            raise MapError("inflation gain and radius must be >= 0")
        reach = base_radius + gain * math.hypot(vx, vy)
        n = int(math.ceil(reach / self.resolution))
        if n == 0:
            return OccupancyGrid(self.occ.copy(), self.resolution)
        occ = self._bordered()
        out = occ.copy()
        rows, cols = occ.shape
        for dr in range(-n, n + 1):
            for dc in range(-n, n + 1):
                if dr == 0 and dc == 0:
                    continue
                # offset d from the free cell to the obstacle cell, in metres
                ox, oy = dc * self.resolution, dr * self.resolution
                dist = math.hypot(ox, oy)
                towards = max(0.0, (vx * ox + vy * oy) / dist)
                if dist > base_radius + gain * towards + 1e-12:
                    continue
                # out[r, c] |= occ[r + dr, c + dc]
                r0, r1 = max(0, -dr), min(rows, rows - dr)
                c0, c1 = max(0, -dc), min(cols, cols - dc)
                if r0 < r1 and c0 < c1:
                    out[r0:r1, c0:c1] |= occ[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
        return OccupancyGrid(out[1:-1, 1:-1], self.resolution)

    def replace(self, occ: np.ndarray) -> None:
        """New obstacles of the same shape, in place (holders of this grid see them); caches dropped."""
        occ = np.asarray(occ, dtype=bool)
        if occ.shape != self.occ.shape:
            raise ValueError(f"replace: shape {occ.shape} is not the grid's {self.occ.shape}")
        self.occ[...] = occ
        self._clearance = self._free_labels = None

    def mark(self, cells: np.ndarray) -> None:
        """Make the cells ``(K, 2)`` [row, col] obstacles, in place (e.g. obstacles sensed on the way)."""
        cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        if len(cells):
            self.occ[cells[:, 0], cells[:, 1]] = True
            self._clearance = self._free_labels = None   # the caches of the map before

    def clearance(self) -> np.ndarray:
        """Distance (m) from each cell centre to the nearest obstacle cell centre (0 inside
        obstacles); the map border counts as far away (outside is not an obstacle here)."""
        if self._clearance is None:
            if self.occ.any():
                self._clearance = ndimage.distance_transform_edt(~self.occ) * self.resolution
            else:
                self._clearance = np.full(self.occ.shape, np.inf)
        return self._clearance

    def clearance_at(self, x: float, y: float) -> float:
        if not self.contains(x, y):
            return 0.0
        r, c = self.cell_of(x, y)
        return float(self.clearance()[r, c])
