"""The figures of ``cdprctl report``, one function each, from a ``Recording``. Every time plot
shares the recording's time axis (s from the first state), marks the run's events (state
changes, faults, rejected commands: a vertical line each, short labels along the top) and
shades the spans where the robot was not tracking (drives off or still enabling): there the
reference is stale and what would read as a tracking error is none."""

from __future__ import annotations

from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from cdprctl.telemetry.report.recording import Event, Recording, column, farthest_pair, read_csv

#: the colour of an event's line by its kind; a state change into these states is red too
EVENT_COLOURS = {"fault": "red", "reject": "darkorange", "event": "0.35"}
ALARM_STATES = {"fault": "FAULT", "estop": "E-STOP", "stopping": "STOPPING"}
#: words that start an alarm's text (the e-stop's own events, a fault during a stop)
ALARM_WORDS = ("emergency stop", "fault")
NOT_TRACKING = "drives off / not tracking"
#: events closer than this fraction of the run share one label (their lines stay apart)
MERGE_FRACTION = 0.015


# -- events and spans ------------------------------------------------------------------------


def event_label(e: Event) -> str:
    """A few words for the figure: the new state of a state change, "FAULT ..." for a fault
    (its clearing too), what a rejection rejected."""
    text = e.text.strip()
    if e.kind == "fault":
        return f"fault: {_short(text.split(':')[0], 34)}" if text else "fault cleared"
    if e.kind == "reject":
        return _short(text.split(":")[0], 28)
    if text.startswith("state ") and "->" in text:
        new, _, why = text.split("->", 1)[1].partition(":")
        new = new.strip()
        label = ALARM_STATES.get(new, new)
        stop = why.strip().split(":")[0]
        return f"{label} ({stop})" if stop.startswith("stop category") else label
    return _short(text.split(":")[0], 28)


def _short(text: str, n: int) -> str:
    """``text`` cut to at most ``n`` characters at a word's end, "…" saying so."""
    if len(text) <= n:
        return text
    return text[: n - 1].rsplit(" ", 1)[0] + "…"


def event_colour(e: Event) -> str:
    label = event_label(e)
    if label == "fault cleared":
        return EVENT_COLOURS["event"]
    if e.kind == "event" and (label in ALARM_STATES.values()
                              or label.lower().startswith(ALARM_WORDS)):  # fmt: skip
        return "red"
    return EVENT_COLOURS.get(e.kind, "C0")


def drawn_events(events: list[Event]) -> list[Event]:
    """The events drawn as instants: not the drives' identities (kind "drives")."""
    return [e for e in events if e.kind != "drives"]


def group_label(group: list[Event]) -> str:
    """One label for events at about the same instant: each label once, none that another
    one says already (an e-stop's own words beside its fault's), at most 40 characters."""
    labels = list(dict.fromkeys(event_label(e) for e in group))
    kept = [a for a in labels
            if not any(a != b and a.lower() in b.lower() for b in labels)]  # fmt: skip
    text = ", ".join(kept)
    return _short(text, 40)


def mark_events(axes: list[Any], events: list[Event], span: float, labelled: list[Any]) -> None:
    """A vertical line per event on each of ``axes``; the ``labelled`` ones carry the labels
    as ticks along their top (outside the data), events within MERGE_FRACTION of ``span`` s
    sharing one."""
    events = drawn_events(events)
    for ax in axes:
        for e in events:
            ax.axvline(e.time, color=event_colour(e), lw=0.8, alpha=0.7, zorder=1,
                       gid="event")  # fmt: skip
    groups: list[list[Event]] = []
    for e in events:
        if groups and e.time - groups[-1][0].time <= MERGE_FRACTION * max(span, 1e-9):
            groups[-1].append(e)
        else:
            groups.append([e])
    ticks = [g[0].time for g in groups]
    words = [group_label(g) for g in groups]
    for ax in labelled:
        top = ax.secondary_xaxis("top")
        top.set_xticks(ticks, words, rotation=90, fontsize=6)
        for tick, g in zip(top.get_xticklabels(), groups, strict=True):
            tick.set_color(next((event_colour(e) for e in g if event_colour(e) == "red"),
                                event_colour(g[0])))  # fmt: skip


def not_tracking_spans(t: np.ndarray, tracking: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) s of each run of rows where the robot is not tracking; a span ends at the
    first tracking row's time (the last row's time at the end)."""
    spans = []
    start = None
    for k, on in enumerate(tracking):
        if not on and start is None:
            start = float(t[k])
        elif on and start is not None:
            spans.append((start, float(t[k])))
            start = None
    if start is not None:
        spans.append((start, float(t[-1])))
    return spans


def shade_not_tracking(ax: Any, rec: Recording, label: bool = True) -> None:
    for k, (a, b) in enumerate(not_tracking_spans(rec.t, rec.tracking())):
        ax.axvspan(a, b, color="0.9", zorder=0, lw=0,
                   label=NOT_TRACKING if label and k == 0 else None)  # fmt: skip


def time_axes(rec: Recording, axes: list[Any], top: list[Any], shade: bool = True) -> None:
    """What every time plot of the state has: the drives-off spans, the events, seconds."""
    for ax in axes:
        if shade:
            shade_not_tracking(ax, rec, label=ax is axes[0])
        ax.set_xlim(0.0, max(float(rec.t[-1]), 1e-3))
    mark_events(axes, rec.events, float(rec.t[-1]), top)


EVENT_KINDS = (("0.35", "event: state change"), ("darkorange", "event: command rejected"),
               ("red", "event: fault, e-stop"), ("C0", "event: other"))


def event_handles(events: list[Event]) -> list[Any]:
    """Legend entries for the kinds of event lines drawn."""
    from matplotlib.lines import Line2D

    drawn = {event_colour(e) for e in drawn_events(events)}
    return [Line2D([], [], color=c, lw=0.8, alpha=0.7, label=words)
            for c, words in EVENT_KINDS if c in drawn]  # fmt: skip


def legend_outside(ax: Any, events: list[Event] | None = None) -> None:
    """The legend to the right of the axes (never over the data), with the event kinds."""
    handles, _ = ax.get_legend_handles_labels()
    handles += event_handles(events or [])
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
              borderaxespad=0.0)  # fmt: skip


# -- the figures ---------------------------------------------------------------------------


def pose_figure(rec: Recording) -> Figure:
    """Position and reference (m) per axis, orientation error (mrad) where tracking."""
    # estimated, reference and true coincide to a fraction of a mm: a wide pale band under two
    # thin lines keeps all three visible where they overlap
    fig, axes = plt.subplots(3, 2, sharex=True, figsize=(13, 7.5), layout="constrained")
    tracking = rec.tracking()
    for ax, a in zip(axes[:, 0], "xyz", strict=True):
        ax.plot(rec.t, rec.column(a), color="C0", lw=4, alpha=0.35, label="estimated")
        ax.plot(rec.t, rec.column(f"ref_{a}"), color="k", lw=1, ls="--", label="reference")
        true = rec.column(f"true_{a}") if rec.has(f"true_{a}") else np.array([np.nan])
        if np.any(np.isfinite(true)):
            ax.plot(rec.t, true, color="C3", lw=1, ls=":", label="simulated (true)")
        ax.set_ylabel(f"{a} (m)")
    for ax, a, name in zip(axes[:, 1], ("rx", "ry", "rz"), "xyz", strict=True):
        err = np.where(tracking, rec.column(f"err_{a}"), np.nan) * 1e3
        ax.plot(rec.t, err, color="C2", lw=1)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"orientation error\nabout {name} (mrad)")
    time_axes(rec, list(axes[:, 0]), [axes[0, 0]])
    time_axes(rec, list(axes[:, 1]), [axes[0, 1]])
    handles = axes[0, 0].get_legend_handles_labels()[0] + event_handles(rec.events)
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"{rec.meta.get('robot', '')}: platform position and reference, base "
                 "frame (left); orientation error, estimate − reference, where tracking "
                 "(right)")  # fmt: skip
    return fig


def tracking_figure(rec: Recording) -> Figure:
    """|estimate − reference| of the position (mm), only where the robot tracks."""
    fig, ax = plt.subplots(figsize=(11, 4.5), layout="constrained")
    err = rec.position_error_mm()
    ax.plot(rec.t, err, color="C0", lw=1, label="tracking error")
    time_axes(rec, [ax], [ax])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position tracking error (mm)")
    ax.set_ylim(bottom=0.0)
    legend_outside(ax, rec.events)
    if np.any(np.isfinite(err)):
        summary = (f"RMS {np.sqrt(np.nanmean(err**2)):.2f} mm, max {np.nanmax(err):.2f} mm, "
                   "while tracking")  # fmt: skip
    else:
        summary = "no row while tracking (the drives never on): nothing to measure"
    ax.set_title(f"position tracking error |estimate − reference|: {summary}", fontsize=10)
    return fig


def _per_cable(ax: Any, t: Any, series: list[Any], what: str, names: list[str]) -> None:
    """One line per cable: a symmetric robot's cables pull alike, so lines lie on lines —
    each cable its colour and one of four styles, wide under narrow, so every one shows."""
    styles = ("-", "--", ":", "-.")
    for k, (y, c) in enumerate(zip(series, names, strict=True)):
        ax.plot(t, y, ls=styles[k % 4], lw=2.6 - 0.5 * (k % 4), color=f"C{k % 10}",
                label=f"{what} {c}", zorder=2 + k % 4)  # fmt: skip


def tensions_figure(rec: Recording) -> Figure:
    """Each cable's commanded tension (N) with the limits (the ARK 2020 paper's Fig. 5)."""
    fig, ax = plt.subplots(figsize=(11, 5), layout="constrained")
    _per_cable(ax, rec.t, [rec.column(f"t_{c}") for c in rec.cables], "cable", rec.cables)
    lo, hi = rec.meta.get("tension_min"), rec.meta.get("tension_max")
    if lo and hi:
        ax.axhline(min(lo), color="k", ls="--", lw=1, label="t_min")
        ax.axhline(max(hi), color="r", ls="--", lw=1, label="t_max")
    time_axes(rec, [ax], [ax])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("commanded tension (N)")
    legend_outside(ax, rec.events)
    ax.set_title("cable tensions (cables that pull alike overlap: told apart by line style; "
                 "drives off: computed, not applied)", fontsize=10)  # fmt: skip
    return fig


def torques_figure(rec: Recording) -> Figure:
    """Each winch's motor torque (N·m) with the limit."""
    fig, ax = plt.subplots(figsize=(11, 4.5), layout="constrained")
    _per_cable(ax, rec.t, [rec.column(f"tau_{c}") for c in rec.cables], "winch", rec.cables)
    limits = rec.meta.get("torque_limit")
    if limits:
        ax.axhline(max(limits), color="r", ls="--", lw=1, label="torque limit")
    time_axes(rec, [ax], [ax])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("motor torque (N·m)")
    legend_outside(ax, rec.events)
    ax.set_title("motor torques (winches that pull alike overlap: told apart by line style)",
                 fontsize=10)  # fmt: skip
    return fig


def grippers_figure(rec: Recording) -> Figure | None:
    """Travel (mm), squeeze (N) and grasp state of each gripper, as sensed from the drives."""
    if not rec.grippers:
        return None
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, sharex=True, figsize=(11, 8),
                                        layout="constrained")
    code = {"open": 0, "contact": 1, "squeezing": 2}
    i_state = {g: rec.head.index(f"grip_state_{g}") for g in rec.grippers}
    for k, g in enumerate(rec.grippers):
        ax1.plot(rec.t, rec.column(f"grip_travel_{g}") * 1e3, color=f"C{k}",
                 label=f"gripper {g}")  # fmt: skip
        ax1.plot(rec.t, rec.column(f"grip_target_{g}") * 1e3, "--", color=f"C{k}", lw=1,
                 label=f"gripper {g} target")  # fmt: skip
        ax2.plot(rec.t, rec.column(f"grip_force_{g}"), color=f"C{k}", label=f"gripper {g}")
        states = [code.get(r[i_state[g]], np.nan) for r in rec.rows]
        ax3.step(rec.t, states, where="post", color=f"C{k}", label=f"gripper {g}")
    ax1.set_ylabel("jaw travel δ (mm)")
    ax2.set_ylabel("estimated squeeze (N)")
    ax3.set_yticks([0, 1, 2], ["open", "contact", "squeezing"])
    ax3.set_ylabel("grasp state")
    ax3.set_xlabel("time (s)")
    time_axes(rec, [ax1, ax2, ax3], [ax1])
    legend_outside(ax1, rec.events)
    for ax in (ax2, ax3):
        legend_outside(ax)
    fig.suptitle("grippers, sensed from the drives (Sensors 2019 §2.4)")
    return fig


def timing_figure(rec: Recording) -> Figure | None:
    """The loop's wake lateness (µs) and missed periods per report window, on the state's time
    axis, and the compute time's distribution."""
    path = rec.run / "timing.csv"
    if not path.is_file():
        return None
    th, tr = read_csv(path)
    if not tr:
        return None
    fig, (ax1, ax3, ax2) = plt.subplots(1, 3, figsize=(15, 4.5), layout="constrained")
    tt = column(th, tr, "time") - rec.t0
    for key in ("lateness_p50_us", "lateness_p99_us", "lateness_max_us"):
        ax1.plot(tt, column(th, tr, key), label=key.replace("lateness_", "").replace("_us", ""))
    ax1.set_yscale("symlog", linthresh=1.0)
    ax1.set_ylabel("wake lateness per report window (µs)")
    ax1.legend(fontsize=7, loc="lower right", title="lateness", title_fontsize=7)
    # "missed" counts from the daemon's start: each window's own is the difference
    total = np.nan_to_num(column(th, tr, "missed"))
    per_window = np.diff(total, prepend=total[0])
    width = 0.8 * float(np.median(np.diff(tt))) if len(tt) > 1 else 0.5
    ax3.bar(tt, per_window, width=width, color="C3")
    ax3.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax3.set_ylabel("missed periods per report window")
    ax3.set_title(f"{int(total[-1] - total[0])} missed in the recording", fontsize=9)
    for ax in (ax1, ax3):  # the state plots' time axis, events and all
        ax.set_xlabel("time (s)")
        ax.set_xlim(-0.5 * width, float(rec.t[-1]) + 0.5 * width)
    mark_events([ax1, ax3], rec.events, float(rec.t[-1]), [ax1, ax3])
    ax2.hist(column(th, tr, "compute_p50_us"), bins=20)
    ax2.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax2.set_xlabel("compute per cycle, median of each report window (µs)")
    ax2.set_ylabel("report windows")
    fig.suptitle("loop timing")
    return fig


def scene_picks(rec: Recording) -> list[tuple[int, str]]:
    """The rows drawn in 3-D and why: the start, the end, and the two poses of the run
    farthest apart (exactly, over every row's estimated position: ``farthest_pair``),
    in time order; a row that is two of these is drawn once, named for both."""
    i, j = farthest_pair(rec.positions())
    d = float(np.linalg.norm(rec.positions()[i] - rec.positions()[j]))
    pair = f"farthest pair ({d:.3f} m apart)"
    why: dict[int, list[str]] = {}
    for k, name in ((0, "start"), (i, pair), (j, pair), (len(rec.rows) - 1, "end")):
        if name not in why.setdefault(k, []):
            why[k].append(name)
    return [(k, ", ".join(why[k])) for k in sorted(why)]


def scene_figure(rec: Recording, path: str) -> bool:
    """scene.png: the robot in 3-D (the live view's scene, docs/foxglove.md) at ``scene_picks``;
    False without the robot's layout in meta.json."""
    if not rec.meta.get("layout"):
        return False
    from cdprctl.telemetry.foxglove.scene import SceneLayout
    from cdprctl.telemetry.report.scene_plot import scene_stills

    layout = SceneLayout.from_dict(rec.meta["layout"])
    names = list(layout.names)
    states = [(f"{why}: t = {rec.t[k]:.1f} s, {rec.states[k]}", _scene_state(rec, k, names))
              for k, why in scene_picks(rec)]  # fmt: skip
    scene_stills(path, layout, states,
                 f"{rec.meta.get('robot', '')}: the robot at the start, the end and the two "
                 "poses of the run farthest apart", trace=rec.positions())  # fmt: skip
    return True


def _scene_state(rec: Recording, k: int, cables: list[str]) -> dict[str, Any]:
    """Row ``k`` as the part of a state payload the scene draws."""
    r = rec.rows[k]

    def value(name: str) -> float:
        x = r[rec.head.index(name)] if rec.has(name) else ""
        return float(x) if x not in ("", "None") else float("nan")

    return {
        "pose": {"position": [value(a) for a in "xyz"],
                 "rpy": [value(a) for a in ("roll", "pitch", "yaw")]},
        "target": [value(f"ref_{a}") for a in ("x", "y", "z", "rx", "ry", "rz")],
        "tensions": [value(f"t_{c}") for c in cables],
        "grippers": [{"travel": value(f"grip_travel_{g}")} for g in rec.grippers],
    }  # fmt: skip
