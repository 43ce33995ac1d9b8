"""Line-of-sight path following on a polyline (Fossen, Breivik and Skjetne 2003).

The local path (Dubins-smoothed, densely sampled) is a polyline in NED. For the vessel's position
the guidance finds the closest point ahead of the last progress, the cross-track error ``e``
(positive to starboard of the path) and commands

    psi_d = pi_p - atan(e / Delta)

where ``pi_p`` is the path-tangential angle and ``Delta`` the look-ahead distance. The progress
along the path only moves forward, so a path that folds back on itself is followed in order.

The closest-point search and the curvature preview run compiled (numba, :func:`_closest` and
:func:`_max_between`): on the <= 50 segments of a window, a dozen numpy calls cost ~35 us a frame
in the vessel computer's lockstep turn; compiled, ~2 us. They do numpy's arithmetic in numpy's order
(tests/test_guidance_kernel.py checks them bit for bit against the numpy expressions they replace).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

WINDOW = 50   # segments ahead of the last progress searched for the closest point


@njit(cache=True, error_model="numpy")
def _closest(path: np.ndarray, seg: np.ndarray, seg_len: np.ndarray, lo: int, hi: int,
             north: float, east: float) -> tuple[int, float]:
    """(segment, fraction along it) of the point of segments lo..hi-1 closest to (north, east):
    the first of equally close ones (np.argmin's rule, a NaN distance counting as the closest).

    The same operations as ``s = clip(einsum("ij,ij->i", p - a, d) / (ln * ln), 0, 1)``,
    ``gap = a + s[:, None] * d - p`` and ``argmin(einsum("ij,ij->i", gap, gap))``: einsum sums
    each row from zero, in order."""
    best_k, best_s, best = lo, 0.0, np.inf
    for k in range(lo, hi):
        a0, a1, d0, d1, ln = path[k, 0], path[k, 1], seg[k, 0], seg[k, 1], seg_len[k]
        dot = 0.0
        dot += (north - a0) * d0
        dot += (east - a1) * d1
        s = dot / (ln * ln)
        # np.maximum/np.minimum: NaN passes through, and max(-0.0, 0.0) is -0.0
        if s < 0.0:
            s = 0.0
        if s > 1.0:
            s = 1.0
        g0 = a0 + s * d0 - north
        g1 = a1 + s * d1 - east
        dist = 0.0
        dist += g0 * g0
        dist += g1 * g1
        if math.isnan(dist):
            return k, s
        if k == lo or dist < best:
            best_k, best_s, best = k, s, dist
    return best_k, best_s


@njit(cache=True)
def _search(a: np.ndarray, v: float, right: bool) -> int:
    """``np.searchsorted(a, v, side="right" if right else "left")`` for a sorted float array: numpy's
    binary search and order (NaN after every number). Written out because numba's brings its own
    helpers, compiled once per side (~0.6 s of a cold compile); ``right`` is passed as ``np.bool_``
    so that this compiles once (a literal True/False would be a type of its own)."""
    lo, hi = 0, len(a)
    v_nan = math.isnan(v)
    while lo < hi:
        mid = lo + ((hi - lo) >> 1)
        m = a[mid]
        # right: m <= v (every m when v is NaN); left: m < v (NaN last: a number below a NaN v)
        below = (v_nan or m <= v) if right else (m < v or (v_nan and not math.isnan(m)))
        if below:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, error_model="numpy")
def _max_between(values: np.ndarray, cum: np.ndarray, index: int, limit: float) -> float:
    """max(values[index:max(index, searchsorted(cum, limit, "right") - 1)]), 0 when empty (NaN wins, as in numpy)."""
    hi = _search(cum, limit, np.bool_(True))
    out, found = 0.0, False
    for j in range(index, min(max(index, hi - 1), len(values))):   # a slice stops at the end
        v = values[j]
        if math.isnan(v):
            return v
        if not found or v > out:
            out, found = v, True
    return out


@njit(cache=True)
def _block_sum(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's sum of ``a[lo:lo + n]`` for ``n`` <= 128: 8 accumulators, from -0.0 below 8."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's sum of ``a[lo:lo + n]`` (float64, contiguous), in its order: pairwise, halves rounded
    down to a multiple of 8, blocks of <= 128 by :func:`_block_sum` (tests/test_guidance_kernel.py
    compares it with np.sum). numpy recurses; this walks the same tree on a stack (a recursive
    numba function took ~3 s of a cold compile, this ~0.5 s)."""
    if n == 0:
        return 0.0   # numpy's empty sum is +0.0 (a block of fewer than 8 starts from -0.0)
    if n <= 128:
        return _block_sum(a, lo, n)
    los = np.empty(64, np.int64)   # a depth of 64 halvings covers any array
    ns = np.empty(64, np.int64)
    state = np.zeros(64, np.int64)   # 0: left half next, 1: right half next, 2: add the two
    sums = np.empty(64)
    top, k = 0, 0
    los[0], ns[0] = lo, n
    while top >= 0:
        m = ns[top]
        if m <= 128:
            sums[k] = _block_sum(a, los[top], m)
            k += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if state[top] == 2:
            sums[k - 2] = sums[k - 2] + sums[k - 1]
            k -= 1
            top -= 1
            continue
        right = state[top] == 1
        state[top] += 1
        los[top + 1] = los[top] + half if right else los[top]
        ns[top + 1] = m - half if right else half
        state[top + 1] = 0
        top += 1
    return sums[0]


@njit(cache=True, error_model="numpy")
def _curvature_at(signed: np.ndarray, cum: np.ndarray, index: int, along: float, span: float) -> float:
    """Mean of ``signed[max(lo - 1, 0):max(hi - 1, 0)]`` with lo, hi the searchsorted positions of
    ``cum[index] + along -/+ span`` (left, right), 0 when empty: LineOfSight.curvature_at's rule."""
    s = cum[index] + along
    lo = max(_search(cum, s - span, np.bool_(False)) - 1, 0)
    hi = min(max(_search(cum, s + span, np.bool_(True)) - 1, 0), len(signed))
    if hi <= lo:
        return 0.0
    return _pairwise_sum(signed, lo, hi - lo) / (hi - lo)


@njit(cache=True, error_model="numpy")
def _follow(path: np.ndarray, seg: np.ndarray, seg_len: np.ndarray, cum: np.ndarray, vertex_curvature: np.ndarray,
            signed_curvature: np.ndarray, lo: int, hi: int, north: float, east: float, lookahead: float,
            preview: float) -> tuple[int, float, float, float, float, float, float]:
    """One LineOfSight.update in one call: (segment, heading, cross-track, remaining, distance to the
    end, curvature ahead, curvature), each term as the Python version computed it."""
    i, s = _closest(path, seg, seg_len, lo, hi, north, east)
    pi_p = math.atan2(seg[i, 1], seg[i, 0])
    # Cross-track error in the path frame: positive to starboard (right of the direction of travel).
    e = -(north - path[i, 0]) * math.sin(pi_p) + (east - path[i, 1]) * math.cos(pi_p)
    along = s * seg_len[i]
    remaining = cum[-1] - (cum[i] + along)
    last = path.shape[0] - 1
    end_dist = np.hypot(path[last, 0] - north, path[last, 1] - east)
    heading = pi_p - math.atan2(e, lookahead)
    if remaining < lookahead:   # near the end, aim at the end point itself
        heading = math.atan2(path[last, 1] - east, path[last, 0] - north) if end_dist > 1e-6 else pi_p
    ahead = _max_between(vertex_curvature, cum, i, cum[i] + along + preview)
    return i, heading, e, remaining, end_dist, ahead, _curvature_at(signed_curvature, cum, i, along, 1.0)


_warm = False


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels once per process, before the first frame."""
    global _warm
    if not _warm:
        LineOfSight(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]]), 1.0, 0.5).update(0.5, 0.1, 1.0)
        _warm = True


@dataclass(frozen=True)
class GuidanceOutput:
    heading: float          # rad, desired heading (NED, clockwise from north)
    cross_track: float      # m, positive when the vessel is to starboard of the path
    remaining: float        # m, path length from the closest point to the end
    finished: bool          # within the acceptance radius of the end point
    curvature_ahead: float  # 1/m, the sharpest turn of the path within the preview distance
    curvature: float = 0.0  # 1/m, signed (> 0 turning to starboard) path curvature at the closest point


class LineOfSight:
    """LOS guidance along an NED polyline ``path`` of shape (N, 2) (north, east)."""

    def __init__(self, path: np.ndarray, lookahead: float, acceptance_radius: float) -> None:
        path = np.asarray(path, dtype=float)
        if path.ndim != 2 or path.shape[1] != 2 or len(path) < 2:
            raise ValueError("path must be an (N >= 2, 2) array of NED points")
        seg = np.diff(path, axis=0)
        keep = np.hypot(seg[:, 0], seg[:, 1]) > 1e-9
        self.path = np.vstack([path[:1], path[1:][keep]])
        if len(self.path) < 2:
            raise ValueError("path has no length")
        self.seg = np.diff(self.path, axis=0)
        self.seg_len = np.hypot(self.seg[:, 0], self.seg[:, 1])
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.lookahead = lookahead
        self.acceptance_radius = acceptance_radius
        self.index = 0  # segment of the last progress
        # Discrete curvature at each interior vertex: turning angle over the mean adjacent length.
        ang = np.arctan2(self.seg[:, 1], self.seg[:, 0])
        turn = np.abs((np.diff(ang) + np.pi) % (2.0 * np.pi) - np.pi)
        self.vertex_curvature = turn / np.maximum(0.5 * (self.seg_len[:-1] + self.seg_len[1:]), 1e-6)
        signed = (np.diff(ang) + np.pi) % (2.0 * np.pi) - np.pi
        self.signed_curvature = signed / np.maximum(0.5 * (self.seg_len[:-1] + self.seg_len[1:]), 1e-6)

    @property
    def length(self) -> float:
        return float(self.cum[-1])

    def curvature_ahead(self, index: int, along: float, preview: float) -> float:
        """Largest vertex curvature (1/m) between ``along`` metres into segment ``index`` and ``preview`` m on."""
        start = self.cum[index] + along
        # vertex j sits at the end of segment j
        return float(_max_between(self.vertex_curvature, self.cum, index, start + preview))

    def curvature_at(self, index: int, along: float, span: float = 1.0) -> float:
        """Mean signed curvature (1/m, > 0 to starboard) of the vertices within ``span`` m either
        side of ``along`` metres into segment ``index``: the turn a yaw-rate feed-forward follows."""
        return float(_curvature_at(self.signed_curvature, self.cum, index, along, span))

    def update(self, north: float, east: float, preview: float = 0.0) -> GuidanceOutput:
        """Desired heading for the vessel at (north, east); ``preview`` m of path are scanned for curvature."""
        # Search a window ahead of the last progress only, so the vessel never skips back.
        lo, hi = self.index, min(self.index + WINDOW, len(self.seg))
        i, heading, e, remaining, end_dist, ahead, curvature = _follow(
            self.path, self.seg, self.seg_len, self.cum, self.vertex_curvature, self.signed_curvature, lo, hi,
            float(north), float(east), float(self.lookahead), float(preview))
        self.index = i
        return GuidanceOutput(heading=heading, cross_track=e, remaining=remaining,
                              finished=end_dist <= self.acceptance_radius, curvature_ahead=ahead,
                              curvature=curvature)
