"""The picture of one HIL run: chart, uncharted and sensed obstacles, reference path, planned local
paths, true and estimated tracks, current arrows. Drawn in the map frame (x east, y north) like the paper's
Figures 9 and 10."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from autopilot_bridge.summary import AutopilotSummary
    from hil.encounter_report import EncounterVerdict
    from hil.scenario import Scenario
    from hil.settings import HilConfig


def plot_run(path: Path, scen: Scenario, truth: dict[int, tuple], autopilot: AutopilotSummary | None, cfg: HilConfig,
             ships: dict | None = None, encounters: Sequence[EncounterVerdict] | None = None,
             outcome: str | None = None) -> dict:
    """``autopilot``: the autopilot's summary (sensed cells, local paths, estimated track), None when
    it left none; ``ships``: MMSI -> ``hil.encounter_report.ShipTrack`` (their truth); ``encounters``: the
    summary's per-ship report (CPA time and distance, type, compliance); ``outcome``: the run's
    outcome for the title (e.g. "goal reached", "collision at 45.2 s").

    Returns what was drawn: ``{"title", "legend": [labels], "xlabel", "ylabel"}``."""
    fig, ax = plt.subplots(figsize=(10, 10 * scen.height / max(scen.width, 1e-9) * 0.9 + 1))
    ax.imshow(scen.occ, origin="lower", cmap="Greys", extent=(0, scen.width, 0, scen.height),
              interpolation="nearest", alpha=0.85)
    field = scen.map_field()
    if field is not None:
        xs = np.linspace(0, scen.width, 18)
        ys = np.linspace(0, scen.height, int(18 * scen.height / scen.width) + 2)
        X, Y = np.meshgrid(xs, ys)
        U, V = field(X, Y)
        ax.quiver(X, Y, U, V, color="tab:blue", alpha=0.35, width=0.002, label="current (planning)")
    for i, (x, y, r) in enumerate(getattr(scen, "uncharted", ())):
        ax.add_patch(plt.Circle((x, y), r, color="tab:purple", alpha=0.35,
                                label="uncharted obstacles (truth)" if i == 0 else None))
    sensed = np.asarray((autopilot and autopilot.sensed_cells) or [], dtype=float).reshape(-1, 2)
    if len(sensed):
        res = scen.resolution
        ax.plot((sensed[:, 1] + 0.5) * res, (sensed[:, 0] + 0.5) * res, "s", color="tab:purple", ms=2,
                label="sensed obstacles (range sensor)")
    ref = np.asarray(scen.reference_path)
    ax.plot(ref[:, 0], ref[:, 1], ":", color="green", lw=1.5, label="global reference path")
    for i, lp in enumerate((autopilot and autopilot.local_paths) or []):
        p = np.asarray(lp.path_ned)
        if len(p):
            ax.plot(p[:, 1], p[:, 0], "-", color="tab:orange", lw=0.7, alpha=0.6,
                    label="planned local paths" if i == 0 else None)
    if truth:
        tr = np.array([truth[t][:2] for t in sorted(truth)])
        ax.plot(tr[:, 1], tr[:, 0], "-", color="red", lw=1.8, label="true track")
    est = np.asarray((autopilot and autopilot.estimated_track) or [])
    if len(est):
        ax.plot(est[:, 2], est[:, 1], "--", color="black", lw=0.8, label="estimated track")
    _plot_ships(ax, ships or {}, encounters or [], truth)
    ax.plot(*scen.start, "o", color="red", ms=7, ls="none",
            label=f"start ({scen.start[0]:.0f}, {scen.start[1]:.0f}) m")
    ax.plot(*scen.goal, "*", color="gold", ms=16, mec="k", ls="none",
            label=f"goal ({scen.goal[0]:.0f}, {scen.goal[1]:.0f}) m")
    r = cfg.autopilot.goal_tolerance
    ax.add_patch(plt.Circle(scen.goal, r, fill=False, ls="--", color="gold", label=f"goal tolerance {r:g} m"))
    ax.set_xlim(0, scen.width)
    ax.set_ylim(0, scen.height)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    title = f"HIL run: {scen.name}" + (f": {outcome}" if outcome else "")
    ax.set_title(title)
    legend = ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"title": title, "legend": [t.get_text() for t in legend.get_texts()],
            "xlabel": ax.get_xlabel(), "ylabel": ax.get_ylabel()}


def _plot_ships(ax: Axes, ships: dict, encounters: Sequence[EncounterVerdict], truth: dict[int, tuple]) -> None:
    """Each ship's true track, and both vessels where they were at the closest point of approach."""
    by_mmsi = {e.get("mmsi"): e for e in encounters}
    times = np.array(sorted(truth)) if truth else np.zeros(0, dtype=np.int64)
    for i, (mmsi, tr) in enumerate(sorted(ships.items())):
        if not tr.samples:
            continue
        smp = np.array([(t, n, e) for t, n, e, _, _ in tr.samples], dtype=float)
        ax.plot(smp[:, 2], smp[:, 1], "-", color="tab:blue", lw=1.4, label="ship tracks (truth)" if i == 0 else None)
        if len(smp) > 1:   # where she was heading at the end
            ax.annotate("", xy=(smp[-1, 2], smp[-1, 1]), xytext=(smp[-2, 2], smp[-2, 1]),
                        arrowprops=dict(arrowstyle="->", color="tab:blue"))
        enc = by_mmsi.get(mmsi)
        t_cpa = None if enc is None else enc.get("cpa_time_s")
        if enc is None or t_cpa is None or len(times) == 0:
            continue
        k = int(np.argmin(np.abs(smp[:, 0] * 1e-6 - t_cpa)))
        j = int(np.argmin(np.abs(times * 1e-6 - t_cpa)))
        own = truth[int(times[j])]
        ax.plot([smp[k, 2], own[1]], [smp[k, 1], own[0]], ":", color="tab:blue", lw=1)
        ax.plot(smp[k, 2], smp[k, 1], "s", color="tab:blue", ms=6)
        ok = enc.get("compliant")
        verdict = "complied" if ok else ("did not comply" if ok is False else "")
        ax.annotate(f"{mmsi} {enc.get('type', '')}\nCPA {enc.get('cpa_m', float('nan')):.1f} m {verdict}",
                    (smp[k, 2], smp[k, 1]), textcoords="offset points", xytext=(6, 6), fontsize=7, color="tab:blue")
