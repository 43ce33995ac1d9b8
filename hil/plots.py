"""Figures of the planning experiments (matplotlib, Agg backend: no screen needed).

* :func:`plot_plan`      one query: map, tree, path (``hil plan --plot``);
* :func:`plot_online`    Figure 10 style: map with inflated cells shaded, reference path (dotted),
  per-cycle trees (thin lines), local paths, Dubins path (red), perceptual circles (green dashed),
  current arrows (quiver of the field);
* :func:`plot_runs_grid` Figure 11 style: a grid of Monte Carlo runs with their paths.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import ListedColormap

from planner.params import REGISTRY

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from planner.online import OnlineResult
    from planner.result import PlannerResult

# A current in the map frame: (x east, y north) m -> (v_east, v_north) m/s (hil.scenario.MapFrameCurrent)
MapField = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray | float, np.ndarray | float]]


def _draw_map(ax: Axes, occ: np.ndarray, resolution: float, inflated: np.ndarray | None = None) -> None:
    h, w = occ.shape[0] * resolution, occ.shape[1] * resolution
    layer = occ.astype(np.uint8) * 2
    if inflated is not None and inflated.shape == occ.shape:
        layer = np.where(occ, 2, np.where(inflated, 1, 0)).astype(np.uint8)
    cmap = ListedColormap(["white", "#c8c8d8", "#303030"])
    ax.imshow(layer, origin="lower", extent=(0, w, 0, h), cmap=cmap, vmin=0, vmax=2, interpolation="nearest")
    ax.set_xlim(0, w)
    ax.set_ylim(0, h)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")


def _draw_tree(ax: Axes, nodes: np.ndarray, parents: np.ndarray, color: str = "#7a9cc6", lw: float = 0.3) -> None:
    nodes = np.asarray(nodes).reshape(-1, 2)
    parents = np.asarray(parents).reshape(-1)
    if len(nodes) < 2 or len(parents) != len(nodes):
        return
    child = np.nonzero(parents >= 0)[0]
    segs = np.stack([nodes[parents[child]], nodes[child]], axis=1)
    ax.add_collection(LineCollection(list(segs), colors=color, linewidths=lw, alpha=0.7, zorder=2))


def _draw_field(ax: Axes, field: MapField | None, width: float, height: float, n: int = 16) -> None:
    if field is None:
        return
    xs = np.linspace(width / (2 * n), width - width / (2 * n), n)
    ys = np.linspace(height / (2 * n), height - height / (2 * n), max(int(n * height / width), 2))
    X, Y = np.meshgrid(xs, ys)
    U, V = field(X, Y)
    U, V = np.broadcast_to(np.asarray(U, float), X.shape), np.broadcast_to(np.asarray(V, float), X.shape)
    if np.allclose(U, 0) and np.allclose(V, 0):
        return
    ax.quiver(X, Y, U, V, color="#2a8f8f", alpha=0.6, width=0.003, zorder=1)


def _path(ax: Axes, path: np.ndarray, *, color: str | None = None, lw: float | None = None, ls: str = "-",
          zorder: float | None = None, label: str | None = None) -> None:
    """``path`` (N, 2) m as a line; None: matplotlib's default for that Line2D property."""
    path = np.asarray(path).reshape(-1, 2)
    if len(path):
        ax.plot(path[:, 0], path[:, 1], color=color, lw=lw, ls=ls, zorder=zorder, label=label)


def plot_plan(out: str | Path, occ: np.ndarray, resolution: float, start: tuple[float, float],
              goal: tuple[float, float], result: PlannerResult,
              inflated: np.ndarray | None = None, field: MapField | None = None, title: str = "") -> Path:
    """One planning query: map, tree, path, start and goal."""
    fig, ax = plt.subplots(figsize=(7, 7 * occ.shape[0] / occ.shape[1] + 0.5))
    _draw_map(ax, occ, resolution, inflated)
    _draw_field(ax, field, occ.shape[1] * resolution, occ.shape[0] * resolution)
    _draw_tree(ax, result.tree_nodes, result.tree_parents)
    _path(ax, result.path, color="red", lw=1.8, zorder=4, label=f"path ({result.status}, {result.length:.1f} m)")
    ax.plot(*start, "o", color="tab:green", ms=7, zorder=5, label="start")
    ax.plot(*goal, "*", color="tab:orange", ms=12, zorder=5, label="goal")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8)
    return _save(fig, out)


def plot_online(out: str | Path, occ: np.ndarray, resolution: float, runs: Sequence[tuple[str, OnlineResult]],
                reference_path: np.ndarray, start: tuple[float, float], goal: tuple[float, float],
                perceptual_radius: float,
                inflated: np.ndarray | None = None, field: MapField | None = None, title: str = "") -> Path:
    """Figure 10 style, one panel per (label, OnlineResult) in ``runs``."""
    n = max(len(runs), 1)
    aspect = occ.shape[0] / occ.shape[1]
    fig, axes = plt.subplots(1, n, figsize=(6.5 * n, 6.5 * aspect + 0.8), squeeze=False)
    for ax, (label, res) in zip(axes[0], runs, strict=False):
        _draw_map(ax, occ, resolution, inflated)
        _draw_field(ax, field, occ.shape[1] * resolution, occ.shape[0] * resolution)
        ref = np.asarray(reference_path)
        _path(ax, ref, color="black", ls=":", lw=1.3, zorder=3, label="reference path")
        for k, cyc in enumerate(res.cycles):
            _draw_tree(ax, cyc.tree_nodes, cyc.tree_parents)
            _path(ax, cyc.local_path, color="#e0a030", lw=0.8, zorder=3,
                  label="local paths (pruned)" if k == 0 else None)
            ax.add_patch(plt.Circle((cyc.start.x, cyc.start.y), perceptual_radius, fill=False, color="green",
                                    ls="--", lw=0.7, alpha=0.8, zorder=3,
                                    label="perceptual domain" if k == 0 else None))
            ax.plot(*cyc.subgoal, "x", color="purple", ms=4, zorder=4, label="subgoals" if k == 0 else None)
        _path(ax, res.executed, color="red", lw=1.8, zorder=5, label="executed Dubins path")
        ax.plot(*start, "o", color="tab:green", ms=7, zorder=6, ls="none", label="start")
        ax.plot(*goal, "*", color="tab:orange", ms=12, zorder=6, ls="none", label="goal")
        m = res.metrics
        ax.set_title(f"{label}: {'reached' if res.reached else 'FAILED'}, cost {m.get('cost', float('nan')):.1f}, "
                     f"{len(res.cycles)} cycles", fontsize=10)
        ax.legend(loc="lower right", fontsize=7)
    if title:
        fig.suptitle(title)
    return _save(fig, out)


def plot_runs_grid(out: str | Path, panels: Sequence[dict], cols: int = 3, title: str = "") -> Path:
    """Figure 11 style: each panel dict has occ, resolution, start, goal, reference_path and
    ``paths`` = [(label, executed path, reached), ...]."""
    n = max(len(panels), 1)
    cols = min(cols, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    colors = {e.name: e.colour for e in REGISTRY}
    for ax in axes.flat[n:]:
        ax.axis("off")
    for ax, p in zip(axes.flat, panels, strict=False):
        _draw_map(ax, p["occ"], p["resolution"])
        _path(ax, p["reference_path"], color="black", ls=":", lw=1.0)
        for label, path, reached in p["paths"]:
            _path(ax, path, color=colors.get(label, None), lw=1.4, ls="-" if reached else "--", label=label)
        ax.plot(*p["start"], "o", color="tab:green", ms=5, ls="none", label="start")
        ax.plot(*p["goal"], "*", color="tab:orange", ms=9, ls="none", label="goal")
        ax.set_title(p.get("title", ""), fontsize=9)
        ax.set_xlabel("x east (m)", fontsize=8)
        ax.set_ylabel("y north (m)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes.flat[0].legend(loc="upper left", fontsize=7)
    if title:
        fig.suptitle(title)
    return _save(fig, out)


def _save(fig: Figure, out: str | Path) -> Path:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
