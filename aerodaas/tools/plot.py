"""The paper's figures from a recording: ``aerodaas plot RUN.mcap [--out DIR]``.

:func:`plot_run` reads an MCAP recording written by AeroDaaS (a finished one, or a crashed, unfinished one up to
its last complete chunk) and writes PNG files with matplotlib's non-interactive Agg canvas (no pyplot, no GUI):

``trajectory.png``
    Top view of the flight in the robot's local ENU frame (metres east / north of home): the *planned* path
    (dashed, through the waypoints numbered in the order they were commanded), the *flown* path from odometry
    (solid; segments flown while the mission state was ``TRACKING`` in another colour), take-off and landing
    markers, and the ground truth of moving targets (``/world/targets``) as their own lines.
``battery_altitude.png``
    Two stacked panels over mission time (s since the first message of the recording): altitude (m above home,
    ENU z from odometry) and battery charge (%), with the mission-state intervals (``/mission/state``) shaded.
``latency.png``
    Violin plot of per-frame latency (ms) from ``/{robot}/latency``: end-to-end (frame capture to navigation
    command queued), split into DNN inference, post-processing and framework overhead; medians marked and
    printed. Skipped, with a printed note, when the recording has no latency channel.

With several robots in one recording every file name gets a ``_<robot>`` suffix (``trajectory_<robot>.png``).

Where the planned path comes from: the ``/{robot}/mission/plan`` channel when the recording has one (JSON
``{"robot", "t", "missions": [{"name", "priority", "items": [{"id", "local": [x, y, z], ...}]}]}``, one message at
the start and one whenever the queue changes; every waypoint item that ever appears is part of the plan).
Otherwise it is rebuilt from the waypoint commands the drone executed: ``/{robot}/nav/command`` (``waypoint``,
``local`` target) and the ``navigate`` events on ``/{robot}/events``. Either way waypoints are numbered in the
order they were first commanded; planned waypoints never commanded follow in plan order.
"""
from __future__ import annotations

import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from aerodaas.tools.plot_data import RobotRun, RunData, load_plot_data, tracking_segments

__all__ = ["plot_run", "FIGURES"]

FIGURES = ("trajectory", "battery_altitude", "latency")
"""Stems of the PNG files :func:`plot_run` writes (per robot; suffixed ``_<robot>`` with several robots)."""

_DPI = 130
# Fixed colour per mission state so the same state looks the same in every figure and every run.
_STATE_COLORS = {
    "IDLE": "#d9d9d9", "PREFLIGHT": "#bdbdbd", "ARMED": "#969696", "TAKING_OFF": "#9ecae1",
    "HOVERING": "#c7e9c0", "NAVIGATING": "#a1d99b", "WAYPOINT_HOLD": "#fdd0a2", "TRACKING": "#fc9272",
    "PAUSED": "#dadaeb", "RETURNING": "#bcbddc", "LANDING": "#c6dbef", "LANDED": "#f0f0f0",
    "EMERGENCY": "#ef3b2c",
}
_FLOWN_COLOR = "#1f77b4"
_TRACKING_COLOR = "#d62728"
_PLANNED_COLOR = "#555555"
_TARGET_COLORS = ("#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")


def _masked_path(xy: np.ndarray, seg_mask: np.ndarray) -> np.ndarray:
    """Copy of ``xy`` keeping only points that end or start a selected segment (others NaN, breaking the line)."""
    keep = np.zeros(len(xy), dtype=bool)
    keep[:-1] |= seg_mask
    keep[1:] |= seg_mask
    out = xy.astype(float).copy()
    out[~keep] = np.nan
    return out


# --------------------------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------------------------
def _new_figure(w: float, h: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: heavy dependency (matplotlib)
    from matplotlib.figure import Figure  # lazy: heavy dependency (matplotlib)

    fig = Figure(figsize=(w, h), dpi=_DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, out: Path) -> Path:
    fig.savefig(out, format="png", dpi=_DPI, bbox_inches="tight")
    return out


def _subtitle(data: RunData, r: RobotRun) -> str:
    bits = [data.path.name]
    if r.outcome:
        bits.append(f"outcome {r.outcome}")
    if not data.finished:
        bits.append("UNFINISHED recording")
    return " · ".join(bits)


def plot_trajectory(data: RunData, r: RobotRun, out: Path) -> Path:
    """Top view (x east, y north, metres from home): planned path dashed through numbered waypoints, flown path
    solid (TRACKING segments in red), take-off/landing markers, target ground truth lines. Writes ``out`` (PNG)."""
    xy = r.position[:, :2] if len(r.position) else np.zeros((0, 2))
    start = xy[0] if len(xy) else np.zeros(2)
    # size the axes to the data's aspect ratio (equal metres on both axes) so flat or tall flights stay readable
    pts = [xy, np.array([w.local[:2] for w in r.planned]).reshape(-1, 2)] + [t.xy for t in data.targets.values()]
    allp = np.vstack([p for p in pts if len(p)] or [np.zeros((1, 2))])
    allp = allp[np.isfinite(allp).all(axis=1)]
    span = np.ptp(allp, axis=0) if len(allp) else np.ones(2)
    aspect = (max(span[1], 1.0) * 1.16) / (max(span[0], 1.0) * 1.16)
    ax_h = float(np.clip(7.0 * aspect, 2.4, 7.0))  # axes height in inches for a ~7 in wide axes
    fig = _new_figure(9.0, ax_h / 0.77)  # default subplot params give the axes 77 % of the figure height
    ax = fig.add_subplot(1, 1, 1)

    for i, tg in enumerate(data.targets.values()):
        if not np.isfinite(tg.xy).any():
            continue
        color = _TARGET_COLORS[i % len(_TARGET_COLORS)]
        label = f"target {tg.id}" + (f" ({tg.class_name})" if tg.class_name else "") + " ground truth"
        ax.plot(tg.xy[:, 0], tg.xy[:, 1], color=color, lw=2.5, alpha=0.55, label=label, zorder=2)
        ok = np.flatnonzero(np.isfinite(tg.xy[:, 0]))
        ax.plot(*tg.xy[ok[0]], marker="s", ms=7, color=color, zorder=3)
        ax.annotate(f"{tg.id} t={tg.t[ok[0]]:.0f} s", tg.xy[ok[0]], textcoords="offset points", xytext=(4, -12),
                    fontsize=8, color=color)
        if len(ok) > 1:
            a, b = tg.xy[ok[-2]], tg.xy[ok[-1]]
            ax.annotate("", b, a, arrowprops={"arrowstyle": "-|>", "color": color, "lw": 2}, zorder=3)
            ax.annotate(f"t={tg.t[ok[-1]]:.0f} s", b, textcoords="offset points", xytext=(4, 4), fontsize=8,
                        color=color)

    if r.planned:
        wps = np.array([w.local[:2] for w in r.planned])
        path = np.vstack([start[None, :], wps])
        src = {"plan": "mission plan", "commands": "commanded waypoints"}.get(r.plan_source, r.plan_source)
        ax.plot(path[:, 0], path[:, 1], ls=(0, (5, 3)), lw=1.5, color="k", label=f"planned path ({src})",
                zorder=6)
        reached = np.array([w.reached for w in r.planned])
        if reached.any():
            ax.scatter(wps[reached, 0], wps[reached, 1], s=55, facecolors=_PLANNED_COLOR, edgecolors="k",
                       label="waypoint (reached)", zorder=9)
        if (~reached).any():
            ax.scatter(wps[~reached, 0], wps[~reached, 1], s=55, facecolors="white", edgecolors="k",
                       linewidths=1.5, label="waypoint (not reached)", zorder=9)
        for w in r.planned:
            tag = f"{w.order}: {w.id}" if w.order is not None else f"{w.id} (not commanded)"
            ax.annotate(tag, w.local[:2], textcoords="offset points", xytext=(6, 6), fontsize=9, weight="bold",
                        color="#222222", zorder=7,
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7})

    if len(xy):
        seg = tracking_segments(r)
        if len(xy) >= 2:
            ax.plot(*_masked_path(xy, ~seg).T, color=_FLOWN_COLOR, lw=3.2, alpha=0.6, solid_capstyle="round",
                    label="flown (odometry)", zorder=5)
            if seg.any():
                ax.plot(*_masked_path(xy, seg).T, color=_TRACKING_COLOR, lw=3.2, alpha=0.75,
                        solid_capstyle="round", label="flown while TRACKING", zorder=5)
        ax.plot(*xy[0], marker="^", ms=15, color="#2ca02c", mec="k", ls="none",
                label=f"take-off ({r.position[0, 0]:.1f}, {r.position[0, 1]:.1f})", zorder=8)
        landed = bool(r.states) and r.states[-1][1] == "LANDED"
        ax.plot(*xy[-1], marker="v" if landed else "X", ms=15, color="#d62728" if landed else "#7f7f7f", mec="k",
                ls="none", label=(f"landing ({xy[-1, 0]:.1f}, {xy[-1, 1]:.1f})" if landed
                                  else f"last position ({xy[-1, 0]:.1f}, {xy[-1, 1]:.1f}), not landed"), zorder=8)
    else:
        ax.text(0.5, 0.5, "no odometry recorded", transform=ax.transAxes, ha="center", va="center")

    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.08)
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x east of home (m)")
    ax.set_ylabel("y north of home (m)")
    ax.set_title(f"{r.robot}: planned vs flown trajectory (top view, local ENU)\n{_subtitle(data, r)}", fontsize=11)
    from matplotlib.transforms import offset_copy  # lazy: heavy dependency (matplotlib)

    below = offset_copy(ax.transAxes, fig=fig, y=-36, units="points")  # under the x tick labels and axis label
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below, ncol=2, fontsize=8.5,
              frameon=False, markerscale=0.7)
    return _save(fig, out)


def _shade_states(ax: Any, r: RobotRun, t_end: float) -> dict[str, Any]:
    """Shade each mission-state interval on ``ax``; returns state -> patch for the legend."""
    handles: dict[str, Any] = {}
    for i, (t, state) in enumerate(r.states):
        t_next = r.states[i + 1][0] if i + 1 < len(r.states) else max(t_end, t)
        if t_next <= t:
            continue
        h = ax.axvspan(t, t_next, color=_STATE_COLORS.get(state, "#eeeeee"), alpha=0.55, lw=0, zorder=0)
        handles.setdefault(state, h)
    for t, _state in r.states[1:]:
        ax.axvline(t, color="#777777", lw=0.6, ls=":", zorder=1)
    return handles


def plot_battery_altitude(data: RunData, r: RobotRun, out: Path) -> Path:
    """Altitude (m above home) and battery (%) over mission time (s), two stacked panels sharing the time axis,
    mission-state intervals shaded (one fixed colour per state) and transitions as dotted lines. Writes ``out``."""
    fig = _new_figure(10, 6.5)
    ax_alt, ax_bat = fig.subplots(2, 1, sharex=True, gridspec_kw={"hspace": 0.08})
    t_end = float(r.t[-1]) if len(r.t) else (r.states[-1][0] if r.states else 0.0)
    handles: dict[str, Any] = {}
    for ax in (ax_alt, ax_bat):
        handles.update(_shade_states(ax, r, t_end))
        ax.grid(True, alpha=0.3)
    if len(r.t):
        ax_alt.plot(r.t, r.position[:, 2], color="#08519c", lw=1.8)
        ax_bat.plot(r.t, r.battery_pct, color="#a50f15", lw=1.8)
        bat = r.battery_pct[np.isfinite(r.battery_pct)]
        if bat.size:
            lo, hi = float(bat.min()), float(bat.max())
            pad = max(1.0, 0.1 * (hi - lo))
            ax_bat.set_ylim(max(0.0, lo - pad), min(100.0, hi + pad) if hi < 100 else 100.5)
            ax_bat.annotate(f"{bat[0]:.1f} % → {bat[-1]:.1f} %", xy=(0.99, 0.92), xycoords="axes fraction",
                            ha="right", va="top", fontsize=9,
                            bbox={"boxstyle": "round", "fc": "white", "ec": "#bbbbbb", "alpha": 0.8})
        ax_alt.annotate(f"max {np.nanmax(r.position[:, 2]):.1f} m", xy=(0.99, 0.92), xycoords="axes fraction",
                        ha="right", va="top", fontsize=9,
                        bbox={"boxstyle": "round", "fc": "white", "ec": "#bbbbbb", "alpha": 0.8})
    else:
        ax_alt.text(0.5, 0.5, "no odometry recorded", transform=ax_alt.transAxes, ha="center", va="center")
    ax_alt.set_ylabel("altitude above home (m)")
    ax_bat.set_ylabel("battery (%)")
    ax_bat.set_xlabel("mission time (s)")
    ax_alt.set_title(f"{r.robot}: altitude and battery with mission states\n{_subtitle(data, r)}", fontsize=11)
    if handles:
        order = [s for s in _STATE_COLORS if s in handles] + [s for s in handles if s not in _STATE_COLORS]
        ax_bat.legend([handles[s] for s in order], order, title="mission state", loc="upper center",
                      bbox_to_anchor=(0.5, -0.22), ncol=min(len(order), 5), fontsize=8.5, title_fontsize=9,
                      frameon=False)
    return _save(fig, out)


_LATENCY_PARTS = (("e2e_ms", "end-to-end", "#4c72b0"), ("inference_ms", "DNN inference", "#dd8452"),
                  ("post_ms", "post-processing", "#55a868"), ("overhead_ms", "framework overhead", "#c44e52"))
_LATENCY_TICKS = {"e2e_ms": "end-to-end", "inference_ms": "DNN\ninference", "post_ms": "post-\nprocessing",
                  "overhead_ms": "framework\noverhead"}


def plot_latency(data: RunData, r: RobotRun, out: Path) -> Path:
    """Per-frame latency (ms) from ``/{robot}/latency``. Left: violins of end-to-end latency (frame capture to
    navigation command queued), DNN inference, post-processing and framework overhead (end-to-end minus
    inference and post-processing), with interquartile bar, median dot and median/p99 printed. Right: the mean
    end-to-end latency stacked into its three parts. Writes ``out`` (PNG)."""
    fig = _new_figure(10.5, 5.8)
    ax, ax_bar = fig.subplots(1, 2, gridspec_kw={"width_ratios": [4.2, 1], "wspace": 0.32})
    n = 0
    labels = []
    means: dict[str, float] = {}
    for pos, (key, label, color) in enumerate(_LATENCY_PARTS, start=1):
        v = r.latency.get(key, np.zeros(0))
        v = v[np.isfinite(v)]
        n = max(n, v.size)
        labels.append(_LATENCY_TICKS[key])
        if not v.size:
            continue
        means[key] = float(v.mean())
        med = float(np.median(v))
        if v.size >= 2 and np.ptp(v) > 0:
            parts = ax.violinplot([v], positions=[pos], widths=0.7, showmedians=False, showextrema=False)
            for body in parts["bodies"]:
                body.set_facecolor(color)
                body.set_edgecolor("k")
                body.set_alpha(0.6)
            q1, q3 = np.percentile(v, [25, 75])
            ax.vlines(pos, float(v.min()), float(v.max()), color="k", lw=0.8, zorder=3)
            ax.vlines(pos, q1, q3, color="k", lw=4, zorder=3)
        else:  # a single value (or all equal): no distribution to draw
            ax.hlines(med, pos - 0.2, pos + 0.2, color=color, lw=3, zorder=3)
        ax.scatter([pos], [med], marker="o", s=36, color="white", edgecolors="k", zorder=4)
        p99 = float(np.percentile(v, 99))
        ax.annotate(f"median {med:.1f}\np99 {p99:.1f}", (pos + 0.37, med), fontsize=8.5, va="center", zorder=5,
                    bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "#bbbbbb", "alpha": 0.85})
    ax.set_xticks(range(1, len(labels) + 1), labels)
    ax.set_xlim(0.45, len(labels) + 0.95)
    ax.set_ylim(bottom=0)
    ax.set_ylabel("latency per frame (ms)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.set_title("distribution (violin), IQR (bar), median (dot); values in ms", fontsize=9.5)

    bottom = 0.0
    for key, label, color in _LATENCY_PARTS[1:]:
        m = means.get(key, 0.0)
        if m <= 0:
            continue
        ax_bar.bar([0], [m], bottom=bottom, width=0.6, color=color, alpha=0.75, edgecolor="k", label=label)
        if m > 0.06 * max(means.get("e2e_ms", m), 1e-9):
            ax_bar.text(0, bottom + m / 2, f"{m:.1f}", ha="center", va="center", fontsize=8.5)
        bottom += m
    if "e2e_ms" in means:
        ax_bar.hlines(means["e2e_ms"], -0.4, 0.4, color=_LATENCY_PARTS[0][2], lw=2, label="end-to-end")
        ax_bar.annotate(f"{means['e2e_ms']:.1f}", (0.42, means["e2e_ms"]), fontsize=8.5, va="center")
    ax_bar.set_xlim(-0.6, 0.9)
    ax_bar.set_xticks([0], ["mean"])
    ax_bar.set_ylim(bottom=0, top=max(bottom, means.get("e2e_ms", 0.0), 1e-3) * 1.12)
    ax_bar.set_ylabel("mean latency per frame (ms)")
    ax_bar.set_title("mean breakdown", fontsize=9.5)
    ax_bar.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), fontsize=8, frameon=False, ncol=1)
    ax_bar.grid(True, axis="y", alpha=0.3)
    fig.suptitle(f"{r.robot}: per-frame latency, capture → navigation command queued (n = {n} frames)\n"
                 f"{_subtitle(data, r)}", fontsize=11)
    return _save(fig, out)


# --------------------------------------------------------------------------------------------------------------
# entry points
# --------------------------------------------------------------------------------------------------------------
def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "robot"


def default_out_dir(path: str | Path) -> Path:
    """``<stem>_plots/`` next to the recording."""
    p = Path(path)
    return p.with_name(f"{p.stem}_plots")


def plot_run(path: str | Path, out_dir: str | Path | None = None, *,
             note: Callable[[str], None] | None = None) -> dict[str, Path]:
    """Write the figures of recording ``path`` as PNG files into ``out_dir`` (created if missing; default
    ``<stem>_plots/`` next to the recording) and return ``{stem: path}`` for the files written, e.g.
    ``{"trajectory": .../trajectory.png, "battery_altitude": ..., "latency": ...}`` (stems suffixed ``_<robot>``
    when the recording has several robots).

    Figures that cannot be drawn are skipped with a note (``note(str)``, default: printed to stderr): the latency
    figure without a ``/{robot}/latency`` channel, everything for a robot without odometry or state. Raises
    ``FileNotFoundError``/``OSError`` (file cannot be read, output folder cannot be created) and ``ValueError``
    (not an MCAP file).
    """
    if note is None:
        def note(msg: str) -> None:
            print(f"aerodaas plot: note: {msg}", file=sys.stderr)
    data = load_plot_data(path)
    out = Path(out_dir) if out_dir is not None else default_out_dir(path)
    out.mkdir(parents=True, exist_ok=True)
    for n in data.notes:
        note(n)
    if not data.robots:
        note(f"{data.path} has no odometry, mission state or latency channels; nothing to plot")
        return {}
    multi = len(data.robots) > 1
    written: dict[str, Path] = {}
    for name, r in data.robots.items():
        suffix = f"_{_safe(name)}" if multi else ""

        def target(stem: str) -> tuple[str, Path]:
            return stem + suffix, out / f"{stem}{suffix}.png"

        if len(r.t) or r.planned:
            k, p = target("trajectory")
            written[k] = plot_trajectory(data, r, p)
        else:
            note(f"{name}: no odometry or waypoints; skipping the trajectory figure")
        if len(r.t) or r.states:
            k, p = target("battery_altitude")
            written[k] = plot_battery_altitude(data, r, p)
        else:
            note(f"{name}: no odometry or mission states; skipping the battery/altitude figure")
        if r.latency and any(np.isfinite(v).any() for v in r.latency.values()):
            k, p = target("latency")
            written[k] = plot_latency(data, r, p)
        else:
            note(f"{name}: no per-frame latency channel (/{name}/latency); skipping the latency figure")
    return written
