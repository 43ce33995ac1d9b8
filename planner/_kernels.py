"""Small numba kernels shared by the grid map and the tree core.

* ``segment_free``: exact supercover traversal of the occupancy grid (Amanatides & Woo's
  voxel walk). Every cell the closed segment touches is checked, and when the segment passes
  exactly through a cell corner (within 1e-9 cell) both side neighbours are checked too, so a
  path can never slip diagonally between two obstacle cells that share only a corner.
* ``edge_cost``: eq. (12) on one segment with the current sampled on a grid (bilinear).
* ``monotonic_ns``: libc ``clock_gettime(CLOCK_MONOTONIC)`` from inside compiled code (the
  same clock as ``time.monotonic``), so deadlines are checked every iteration.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

if TYPE_CHECKING:
    import numpy as np
    from numba.core.base import BaseContext
    from numba.core.types import Type
    from numba.core.typing.context import BaseContext as TypingContext
    from numba.core.typing.templates import Signature

CORNER_EPS = 1e-9


def _clock_gettime(clock_id: int) -> Callable[[np.ndarray], int]:
    """An intrinsic calling libc clock_gettime(clock_id, buf) on an int64[2] (a timespec)."""

    @intrinsic
    def call(typingctx: TypingContext, buf: Type) -> tuple[Signature, Callable[..., ir.Value]]:
        sig = types.int64(buf)

        def codegen(context: BaseContext, builder: ir.IRBuilder, signature: Signature,
                    args: Sequence[ir.Value]) -> ir.Value:
            arr = context.make_array(signature.args[0])(context, builder, args[0])
            ptr = builder.bitcast(arr.data, ir.IntType(8).as_pointer())
            fnty = ir.FunctionType(ir.IntType(32), [ir.IntType(32), ir.IntType(8).as_pointer()])
            fn = cgutils.get_or_insert_function(builder.module, fnty, "clock_gettime")
            builder.call(fn, [ir.Constant(ir.IntType(32), clock_id), ptr])
            return ir.Constant(ir.IntType(64), 0)

        return sig, codegen

    return call


_clock_gettime_monotonic = _clock_gettime(1)   # CLOCK_MONOTONIC on Linux
_clock_gettime_thread_cpu = _clock_gettime(3)  # CLOCK_THREAD_CPUTIME_ID on Linux


@njit(cache=True)
def monotonic_ns(buf: np.ndarray) -> int:
    """Nanoseconds of CLOCK_MONOTONIC; ``buf`` is a scratch int64[2] (timespec)."""
    _clock_gettime_monotonic(buf)  # numba passes the typing context itself
    return buf[0] * 1_000_000_000 + buf[1]


@njit(cache=True)
def thread_cpu_ns(buf: np.ndarray) -> int:
    """Nanoseconds of the calling thread's CPU clock (time.thread_time_ns's clock on Linux)."""
    _clock_gettime_thread_cpu(buf)  # numba passes the typing context itself
    return buf[0] * 1_000_000_000 + buf[1]


@njit(cache=True)
def cell_blocked(occ: np.ndarray, row: int, col: int) -> bool:
    rows, cols = occ.shape
    if row < 0 or col < 0 or row >= rows or col >= cols:
        return True
    return occ[row, col] != 0


@njit(cache=True)
def segment_free(occ: np.ndarray, res: float, x0: float, y0: float, x1: float, y1: float) -> bool:
    """True if the closed segment (x0, y0)-(x1, y1) (metres) touches no obstacle cell and stays
    inside the map. Cell (r, c) covers [c res, (c+1) res) x [r res, (r+1) res)."""
    gx0 = x0 / res
    gy0 = y0 / res
    gx1 = x1 / res
    gy1 = y1 / res
    ix = int(math.floor(gx0))
    iy = int(math.floor(gy0))
    ex = int(math.floor(gx1))
    ey = int(math.floor(gy1))
    if cell_blocked(occ, iy, ix) or cell_blocked(occ, ey, ex):
        return False
    dx = gx1 - gx0
    dy = gy1 - gy0
    sx = 1 if dx > 0 else -1
    sy = 1 if dy > 0 else -1
    inf = 1e300
    if dx != 0.0:
        tdx = abs(1.0 / dx)
        tmx = ((ix + 1) - gx0) / dx if dx > 0 else (ix - gx0) / dx
    else:
        tdx = inf
        tmx = inf
    if dy != 0.0:
        tdy = abs(1.0 / dy)
        tmy = ((iy + 1) - gy0) / dy if dy > 0 else (iy - gy0) / dy
    else:
        tdy = inf
        tmy = inf
    nmax = abs(ex - ix) + abs(ey - iy) + 4
    for _ in range(nmax):
        if tmx > 1.0 and tmy > 1.0:
            break
        if abs(tmx - tmy) <= CORNER_EPS:
            # through a corner: the two side cells are touched as well
            if cell_blocked(occ, iy, ix + sx) or cell_blocked(occ, iy + sy, ix):
                return False
            ix += sx
            iy += sy
            tmx += tdx
            tmy += tdy
        elif tmx < tmy:
            ix += sx
            tmx += tdx
        else:
            iy += sy
            tmy += tdy
        if cell_blocked(occ, iy, ix):
            return False
    return True


@njit(cache=True)
def polyline_free(occ: np.ndarray, res: float, path: np.ndarray) -> bool:
    """True if every segment of the polyline ``path`` (N, 2), metres, is :func:`segment_free`
    (True for fewer than two points)."""
    for k in range(path.shape[0] - 1):
        if not segment_free(occ, res, path[k, 0], path[k, 1], path[k + 1, 0], path[k + 1, 1]):
            return False
    return True


@njit(cache=True)
def field_at(fvx: np.ndarray, fvy: np.ndarray, fres: float, fox: float, foy: float, x: float,
             y: float) -> tuple[float, float]:
    """Bilinear interpolation of a gridded field, clamped at the edges."""
    rows, cols = fvx.shape
    gx = (x - fox) / fres
    gy = (y - foy) / fres
    gx = min(max(gx, 0.0), cols - 1.0)
    gy = min(max(gy, 0.0), rows - 1.0)
    c0 = min(int(gx), max(cols - 2, 0))
    r0 = min(int(gy), max(rows - 2, 0))
    c1 = min(c0 + 1, cols - 1)
    r1 = min(r0 + 1, rows - 1)
    fx = gx - c0
    fy = gy - r0
    vx = (fvx[r0, c0] * (1 - fx) * (1 - fy) + fvx[r0, c1] * fx * (1 - fy)
          + fvx[r1, c0] * (1 - fx) * fy + fvx[r1, c1] * fx * fy)
    vy = (fvy[r0, c0] * (1 - fx) * (1 - fy) + fvy[r0, c1] * fx * (1 - fy)
          + fvy[r1, c0] * (1 - fx) * fy + fvy[r1, c1] * fx * fy)
    return vx, vy


@njit(cache=True)
def sigmoid_arg(dx: float, dy: float, length: float, vx: float, vy: float,
                gamma_alpha: float) -> tuple[float, bool]:
    """cos(alpha_y) - gamma_alpha sin(alpha_y) for motion (dx, dy) of norm ``length`` in current
    (vx, vy); returns (value, ok) with ok False when the current is zero."""
    nv = math.hypot(vx, vy)
    if nv < 1e-9 or length <= 0.0:
        return 0.0, False
    c = (dx * vx + dy * vy) / (length * nv)
    c = min(1.0, max(-1.0, c))
    s = math.sqrt(max(0.0, 1.0 - c * c))
    return c - gamma_alpha * s, True


@njit(cache=True)
def edge_cost(x0: float, y0: float, x1: float, y1: float, use_field: bool, fvx: np.ndarray, fvy: np.ndarray,
              fres: float, fox: float, foy: float, step: float, d_alpha: float, gamma_alpha: float) -> float:
    """Eq. (12) along a segment, in pieces of at most ``step`` (alpha_y at each midpoint)."""
    dx = x1 - x0
    dy = y1 - y0
    length = math.hypot(dx, dy)
    if not use_field or length == 0.0:
        return length
    if length <= step:  # one piece (then length / step <= 1, so n below is 1): the tree's edges
        vx, vy = field_at(fvx, fvy, fres, fox, foy, x0 + 0.5 * dx, y0 + 0.5 * dy)
        arg, ok = sigmoid_arg(dx, dy, length, vx, vy, gamma_alpha)
        if not ok:
            return length
        return min(length, d_alpha * length / (1.0 + math.exp(arg)))
    n = max(1, int(math.ceil(length / step - 1e-12)))
    piece = length / n
    total = 0.0
    for i in range(n):
        t = (i + 0.5) / n
        vx, vy = field_at(fvx, fvy, fres, fox, foy, x0 + t * dx, y0 + t * dy)
        arg, ok = sigmoid_arg(dx, dy, length, vx, vy, gamma_alpha)
        if not ok:
            total += piece
        else:
            total += min(piece, d_alpha * piece / (1.0 + math.exp(arg)))
    return total
