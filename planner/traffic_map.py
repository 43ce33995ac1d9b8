"""Spatio-temporal occupancy of moving ships for the local planner (section 3.3).

The paper checks tree edges against "the temporal and spatial occupation of the dynamic
obstacle" estimated with the collision cone, and plans "in the areas prescribed by the COLREGs".
Here a ship is a :class:`MovingObstacle`: its position and velocity at the cycle's start time,
its combined radius R (eq. 10) and its rule zones (:func:`planner.colregs.forbidden_zones`).
A point p is occupied at time tau (s after the cycle start) if, with the ship moved to
``f + v tau``, p is within R of it or inside one of its zones (zones in the ship's frame move with
it; "own" zones are fixed to the USV's course line at the cycle start).

The compiled tree core only knows a static grid, so the time a tree node would be reached is
estimated as ``tau = |p - start| / speed`` (the straight-line arrival; a tree path is never
shorter, so the true arrival is later): :func:`paint` marks a cell occupied if it is occupied at
any sampled time in ``[tau, (1 + k) tau + slack]``, which covers detours up to a factor 1 + k and
a speed ``slack`` seconds slower. Samples never become nodes in occupied cells, so the tree grows
only in the rule-allowed, collision-free part of the perceptual domain. The chosen path is then
checked exactly, with the arrival time along its own length (:func:`first_conflict`).

Map frame (x east, y north, m; angles counter-clockwise from east); a ship's starboard is the
clockwise side of its course.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.gridmap import OccupancyGrid


@dataclass(frozen=True)
class Zone:
    """A rectangle in a ship's frame: ``along`` (m ahead along her course) x ``starboard`` (m)."""

    frame: str                       # "target" (moves with the ship) or "own" (the USV's course line)
    along: tuple[float, float]
    starboard: tuple[float, float]
    origin: tuple[float, float] | None = None   # "own": anchor point (default: the cycle's start)
    course: float | None = None                 # "own": anchor course, rad from east (default: start heading)


@dataclass(frozen=True)
class MovingObstacle:
    """A ship at the cycle's start time: map position (m), velocity (m/s), radius R (m), zones."""

    ident: int
    x: float
    y: float
    vx: float
    vy: float
    radius: float
    zones: tuple[Zone, ...] = ()


@dataclass(frozen=True)
class TrafficSnapshot:
    """What one planning cycle knows of the traffic (all at the cycle's start time)."""

    obstacles: tuple[MovingObstacle, ...]
    speed: float                     # m/s, the USV's expected speed along the path
    heading: float                   # rad, the USV's course at the start ("own" zones)
    start: tuple[float, float]       # m, the USV's position at the start
    time_slack: float = 0.3          # k
    time_slack_s: float = 2.0        # s
    samples: int = 6                 # times sampled per window
    horizon: float = 120.0           # s: beyond this arrival time nothing is painted
    speed_factors: tuple[float, ...] = (1.0, 0.6, 0.35)  # tried in turn by planner.online.plan_cycle


def _in_zone(dx: np.ndarray, dy: np.ndarray, hx: float, hy: float, z: Zone) -> np.ndarray:
    along = dx * hx + dy * hy
    stbd = dx * hy - dy * hx          # right-hand perpendicular of (hx, hy) in the map frame
    return (along >= z.along[0]) & (along <= z.along[1]) & (stbd >= z.starboard[0]) & (stbd <= z.starboard[1])


def occupied(px: np.ndarray, py: np.ndarray, tau: np.ndarray, snap: TrafficSnapshot) -> np.ndarray:
    """Boolean array: is point (px, py) occupied at time ``tau`` (s after the start)? Broadcasts."""
    px, py, tau = np.broadcast_arrays(np.asarray(px, float), np.asarray(py, float), np.asarray(tau, float))
    out = np.zeros(px.shape, dtype=bool)
    ch, sh = math.cos(snap.heading), math.sin(snap.heading)
    for ob in snap.obstacles:
        fx = ob.x + ob.vx * tau
        fy = ob.y + ob.vy * tau
        dx, dy = px - fx, py - fy
        out |= dx * dx + dy * dy <= ob.radius * ob.radius
        sp = math.hypot(ob.vx, ob.vy)
        for z in ob.zones:
            if z.frame == "own":
                ox, oy = z.origin if z.origin is not None else snap.start
                zc, zs = (ch, sh) if z.course is None else (math.cos(z.course), math.sin(z.course))
                out |= _in_zone(px - ox, py - oy, zc, zs, z)
            elif sp > 1e-6:
                out |= _in_zone(dx, dy, ob.vx / sp, ob.vy / sp, z)
    return out


def time_window(tau0: np.ndarray, snap: TrafficSnapshot) -> np.ndarray:
    """(samples, ...) arrival times spanning [tau0, (1 + k) tau0 + slack]."""
    f = np.linspace(0.0, 1.0, snap.samples).reshape((-1,) + (1,) * np.ndim(tau0))
    return tau0 + f * (snap.time_slack * tau0 + snap.time_slack_s)


def occupancy_mask(grid: OccupancyGrid, snap: TrafficSnapshot, center: tuple[float, float],
                   radius: float) -> np.ndarray:
    """Cells (bool, grid shape) occupied by the traffic at the estimated arrival time, within
    ``radius`` of ``center`` (the perceptual domain; nothing is painted outside it)."""
    res = grid.resolution
    rows, cols = grid.occ.shape
    c0, c1 = max(int((center[0] - radius) / res), 0), min(int((center[0] + radius) / res) + 1, cols)
    r0, r1 = max(int((center[1] - radius) / res), 0), min(int((center[1] + radius) / res) + 1, rows)
    mask = np.zeros_like(grid.occ, dtype=bool)
    if c1 <= c0 or r1 <= r0 or not snap.obstacles:
        return mask
    xs = (np.arange(c0, c1) + 0.5) * res
    ys = (np.arange(r0, r1) + 0.5) * res
    X, Y = np.meshgrid(xs, ys)
    tau0 = np.hypot(X - snap.start[0], Y - snap.start[1]) / max(snap.speed, 1e-6)
    taus = time_window(tau0, snap)
    occ = occupied(X[None], Y[None], taus, snap).any(axis=0) & (tau0 <= snap.horizon)
    # A cell is painted if any part of it may be occupied: grow by half a cell's diagonal.
    from scipy import ndimage

    occ = ndimage.binary_dilation(occ, iterations=1)
    mask[r0:r1, c0:c1] = occ
    return mask


def paint(grid: OccupancyGrid, snap: TrafficSnapshot, center: tuple[float, float], radius: float,
          keep_free: tuple[float, float] | None = None, keep_radius: float = 0.0) -> OccupancyGrid:
    """``grid`` plus the traffic's occupancy (a new grid). ``keep_free``: a disc of ``keep_radius``
    left free (where the vessel is now: it has to be able to leave a zone it is already in)."""
    mask = occupancy_mask(grid, snap, center, radius)
    if keep_free is not None and keep_radius > 0:
        res = grid.resolution
        rows, cols = grid.occ.shape
        ys, xs = np.ogrid[:rows, :cols]
        mask &= np.hypot((xs + 0.5) * res - keep_free[0], (ys + 0.5) * res - keep_free[1]) > keep_radius
    return OccupancyGrid(grid.occ | mask, grid.resolution)


def first_conflict(path: np.ndarray, snap: TrafficSnapshot, spacing: float = 0.5,
                   slack_s: float | None = None, ignore_within: float = 0.0) -> float | None:
    """Arrival time (s) of the first point of ``path`` occupied at the time the vessel sailing it
    at ``snap.speed`` would be there (or up to ``slack_s`` later), or None if it is free. Points
    within ``ignore_within`` of the start are not checked (the vessel may be leaving a zone)."""
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(path) < 2 or not snap.obstacles:
        return None
    seg = np.hypot(*np.diff(path, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(int(math.ceil(s[-1] / spacing)), 1)
    q = np.linspace(0.0, s[-1], n + 1)
    px, py = np.interp(q, s, path[:, 0]), np.interp(q, s, path[:, 1])
    tau = q / max(snap.speed, 1e-6)
    slack = snap.time_slack_s if slack_s is None else slack_s
    taus = tau[None, :] + np.linspace(0.0, 1.0, 3)[:, None] * slack
    occ = occupied(px[None, :], py[None, :], taus, snap).any(axis=0) & (tau <= snap.horizon)
    # The vessel's own position (first metres) may already be inside a zone it is leaving.
    occ &= np.hypot(px - path[0, 0], py - path[0, 1]) > max(ignore_within, 1e-9)
    idx = np.nonzero(occ)[0]
    return None if len(idx) == 0 else float(tau[idx[0]])


def relax_for_start(snap: TrafficSnapshot) -> TrafficSnapshot:
    """The snapshot without the zones of ships whose zone the USV is already in at the start (a
    late encounter: the rule region cannot be reached any more, only the collision is avoided)."""
    sx, sy = snap.start
    taus = np.linspace(0.0, snap.time_slack_s, 3)
    keep = []
    for ob in snap.obstacles:
        zones_only = TrafficSnapshot((MovingObstacle(ob.ident, ob.x, ob.y, ob.vx, ob.vy, 0.0, ob.zones),),
                                     snap.speed, snap.heading, snap.start)
        if ob.zones and occupied(np.full(3, sx), np.full(3, sy), taus, zones_only).any():
            ob = MovingObstacle(ob.ident, ob.x, ob.y, ob.vx, ob.vy, ob.radius, ())
        keep.append(ob)
    from dataclasses import replace

    return replace(snap, obstacles=tuple(keep))
