"""Obstacles the vessel learns on the way: range-sensor returns placed on the chart's grid.

The chart (the map known a priori) is the planner's map; what it lacks, the range sensor shows.
Each return of an OBSTACLE_DISTANCE scan is placed in the map frame from the navigation
estimate. Returns that the chart already explains (within ``explain_radius`` of a charted
obstacle: the estimate and the sensor both have errors) are not new. Any other cell becomes a
*sensed obstacle* once returns of ``confirm_hits`` scans have fallen in it, so that one stray return does
not close a channel. Sensed obstacles are kept for the rest of the run (a moored boat does not
leave while we pass it).

Frames: scans in the body frame (bearing clockwise from the bow), navigation in NED, the grid in
the planner's map frame (row = north / resolution, column = east / resolution).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import ndimage


@dataclass
class SensingStats:
    scans: int = 0
    returns: int = 0
    explained_by_chart: int = 0
    outside_map: int = 0


class SensedObstacles:
    def __init__(self, chart: np.ndarray, resolution: float, confirm_hits: int = 2,
                 explain_radius: float = 1.0) -> None:
        self.chart = np.asarray(chart, dtype=bool)
        self.resolution = float(resolution)
        self.confirm_hits = int(confirm_hits)
        clearance = ndimage.distance_transform_edt(~self.chart) * self.resolution if self.chart.any() \
            else np.full(self.chart.shape, np.inf)
        self.explained = clearance <= explain_radius
        self.hits = np.zeros(self.chart.shape, dtype=np.uint16)
        self.confirmed = np.zeros(self.chart.shape, dtype=bool)
        self._cells: list[tuple[int, int]] = []
        self.version = 0
        self.stats = SensingStats()
        # compile (or load from numba's cache) before the first scan: no frame pays for it
        _place(np.zeros((0, 1), np.int64), np.zeros((0, 1), np.int64), self.explained, self.hits, self.confirmed,
               self.confirm_hits)

    def add_scan(self, bearings: npt.ArrayLike, ranges: npt.ArrayLike, north: float, east: float, psi: float,
                 sector_width: float = 0.0) -> np.ndarray:
        """Place one scan (sector bearings rad from the bow, ranges m, sectors ``sector_width`` rad
        wide) seen from NED ``north, east``, heading ``psi``; returns the newly confirmed cells
        ``(K, 2)`` [row, col].

        A sector's return lies somewhere on the arc of its range across the sector (OBSTACLE_DISTANCE
        keeps only the nearest range per sector), so the whole arc is considered: the chart explains
        the return if it explains any point of the arc; otherwise every cell of the arc is hit (a
        conservative obstacle, at most ``range x width`` wide).
        """
        self.stats.scans += 1
        d = np.asarray(ranges, dtype=float)
        if len(d) == 0:
            return np.zeros((0, 2), dtype=np.int32)
        self.stats.returns += len(d)
        r, c = arc_cells(bearings, d, north, east, psi, sector_width, self.resolution)
        # The cells in integers, compiled: a dozen numpy calls on a few hundred cells cost more than the work.
        new, outside, explained = _place(r, c, self.explained, self.hits, self.confirmed, self.confirm_hits)
        self.stats.outside_map += outside
        self.stats.explained_by_chart += explained
        if len(new):
            self._cells.extend((int(r), int(c)) for r, c in new.tolist())
            self.version += 1
        return new

    @property
    def count(self) -> int:
        """How many cells have been sensed so far."""
        return len(self._cells)

    def cells(self) -> np.ndarray:
        """All sensed obstacle cells so far, ``(K, 2)`` int32 [row, col], in the order found."""
        return np.array(self._cells, dtype=np.int32).reshape(-1, 2)

    def summary(self) -> dict[str, int]:
        s = self.stats
        return {"scans": s.scans, "returns": s.returns, "explained_by_chart": s.explained_by_chart,
                "outside_map": s.outside_map, "cells": len(self._cells), "versions": self.version}


def arc_cells(bearings: npt.ArrayLike, d: np.ndarray, north: float, east: float, psi: float, sector_width: float,
              res: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid rows and columns ``(R, n_arc)`` int64 of the arcs of returns at ranges ``d`` (m, R > 0),
    each arc sampled at <= half a cell across its sector (one sample count for the scan)."""
    n_arc = int(math.ceil(d.max() * sector_width / (0.5 * res))) + 1 if sector_width > 0 else 1
    spread = np.linspace(-0.5, 0.5, n_arc) * sector_width if n_arc > 1 else np.zeros(1)
    a = psi + np.asarray(bearings, dtype=float)[:, None] + spread[None, :]      # (R, n_arc)
    r = np.floor((north + d[:, None] * np.cos(a)) / res).astype(np.int64)
    c = np.floor((east + d[:, None] * np.sin(a)) / res).astype(np.int64)
    return r, c


@njit(cache=True)
def _sift_down(a: np.ndarray, root: int, end: int) -> None:
    """Restore the max-heap below ``root`` within ``a[:end]``."""
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and a[child + 1] > a[child]:
            child += 1
        if a[root] >= a[child]:
            return
        a[root], a[child] = a[child], a[root]
        root = child


@njit(cache=True)
def _sort_unique(a: np.ndarray, k: int) -> int:
    """Sort ``a[:k]`` in place (heapsort) and move its distinct values to the front, ascending;
    returns how many: ``a[:returned]`` is ``np.unique(a[:k])``. Written out because numba's
    ``np.unique`` brings its quicksort and comparison helpers: ~2 s of a cold compile for this."""
    for start in range(k // 2 - 1, -1, -1):
        _sift_down(a, start, k)
    for end in range(k - 1, 0, -1):
        a[0], a[end] = a[end], a[0]
        _sift_down(a, np.int64(0), end)
    u = 0
    for i in range(k):
        if u == 0 or a[i] != a[u - 1]:
            a[u] = a[i]
            u += 1
    return u


@njit(cache=True)
def _place(r: np.ndarray, c: np.ndarray, explained_map: np.ndarray, hits: np.ndarray, confirmed: np.ndarray,
           confirm_hits: int) -> tuple[np.ndarray, int, int]:
    """The arcs' cells ``r, c`` (R, n_arc) of one scan on the grid: a return whose arc leaves the
    grid entirely is outside the map; one with a cell the chart explains is explained; every cell of
    the other arcs is hit once per scan (neighbouring arcs share edge cells) unless already confirmed,
    and confirmed at ``confirm_hits``. Updates ``hits`` and ``confirmed``; returns the newly confirmed
    cells (K, 2) [row, col] in row-major order, and the counts of returns outside and explained."""
    rows, cols = explained_map.shape
    n_ret, n_arc = r.shape
    cells = np.empty(n_ret * n_arc, np.int64)
    k = outside = explained = 0
    for i in range(n_ret):
        any_inside = by_chart = False
        for j in range(n_arc):
            ri, ci = r[i, j], c[i, j]
            if 0 <= ri < rows and 0 <= ci < cols:
                any_inside = True
                if explained_map[ri, ci]:
                    by_chart = True
        if not any_inside:
            outside += 1
        elif by_chart:
            explained += 1
        else:
            for j in range(n_arc):
                ri, ci = r[i, j], c[i, j]
                if 0 <= ri < rows and 0 <= ci < cols:
                    cells[k] = ri * cols + ci
                    k += 1
    u = _sort_unique(cells, np.int64(k))   # not the literal 0 `k` is typed as first: one compile
    new = np.empty((u, 2), np.int32)
    m = 0
    for a in range(u):
        lin = cells[a]
        ri, ci = lin // cols, lin % cols
        if confirmed[ri, ci]:
            continue
        hits[ri, ci] += 1
        if hits[ri, ci] >= confirm_hits:
            confirmed[ri, ci] = True
            new[m, 0], new[m, 1] = ri, ci
            m += 1
    return new[:m], outside, explained


def path_blocked(path_ned: np.ndarray, cells: np.ndarray, resolution: float, clearance: float) -> bool:
    """Does any cell centre (``(K, 2)`` [row, col], map grid) lie within ``clearance`` (m) of the
    NED polyline ``path_ned`` ``(N, 2)``?"""
    if len(cells) == 0 or len(path_ned) == 0:
        return False
    p = (cells.astype(float) + 0.5) * resolution            # (K, 2) north, east: row ~ north, col ~ east
    a = np.asarray(path_ned, dtype=float)[:-1] if len(path_ned) > 1 else np.asarray(path_ned, dtype=float)
    b = np.asarray(path_ned, dtype=float)[1:] if len(path_ned) > 1 else a
    ab = b - a                                               # (N, 2)
    ap = p[:, None, :] - a[None, :, :]                      # (K, N, 2)
    denom = np.maximum((ab * ab).sum(axis=1), 1e-12)
    t = np.clip((ap * ab[None]).sum(axis=2) / denom, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    d = np.hypot(*(p[:, None, :] - closest).transpose(2, 0, 1))
    return bool((d <= clearance).any())
