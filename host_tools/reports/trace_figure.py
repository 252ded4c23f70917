"""A picture of a trace.pftrace laid out as the Perfetto UI shows it: one row per track, time across.

``python -m host_tools.reports.trace_figure TRACE OUT.png --window A B [--zoom C D]`` draws the tracks between A and
B seconds (and, with ``--zoom``, the same tracks between C and D beside them): slices as bars, instants as
markers named on their track, counters as step lines scaled to their row (their range written at the row's end).
``python -m host_tools.reports.trace_figure --docs`` makes docs/img/trace_stride_fault.png from a real run: one
stride of a 20 kg walk with a control-task overrun that trips the supervisor (the picture in docs/telemetry.md).

The file is read with the perfetto package's schema (``Trace``), independently of the writer's bookkeeping.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

from perfetto.protos.perfetto.trace.perfetto_trace_pb2 import Trace, TrackEvent

__all__ = ["TraceView", "docs_figure", "draw", "read_view"]

ROOT = Path(__file__).resolve().parents[2]
DOCS_PNG = ROOT / "docs" / "img" / "trace_stride_fault.png"


@dataclass
class TraceView:
    """A trace's tracks (uuid -> name, parent, rank, counter) and their events, times in seconds."""

    tracks: dict[int, tuple[str, int | None, int, bool]] = field(default_factory=dict)
    slices: dict[int, list[tuple[float, float, str]]] = field(default_factory=dict)
    instants: dict[int, list[tuple[float, str]]] = field(default_factory=dict)
    counters: dict[int, list[tuple[float, float]]] = field(default_factory=dict)

    def rows(self) -> list[int]:
        """The tracks that hold events, in the UI's order: by group, then by rank."""
        def key(uuid: int) -> tuple[int, int]:
            name, parent, rank, _ = self.tracks[uuid]
            return (self.tracks[parent][2] if parent is not None else rank, rank)
        used = set(self.slices) | set(self.instants) | set(self.counters)
        return sorted(used, key=key)


def read_view(path: Path) -> TraceView:
    """Read a trace.pftrace into a :class:`TraceView`."""
    view = TraceView()
    names: dict[int, str] = {}
    open_: dict[int, list[tuple[float, str]]] = {}
    for p in Trace.FromString(Path(path).read_bytes()).packet:
        if p.HasField("track_descriptor"):
            d = p.track_descriptor
            view.tracks[d.uuid] = (d.name, d.parent_uuid if d.HasField("parent_uuid") else None,
                                   d.sibling_order_rank, d.HasField("counter"))
        names.update({e.iid: e.name for e in p.interned_data.event_names})
        if not p.HasField("track_event"):
            continue
        e, t = p.track_event, p.timestamp / 1e9
        if e.type == TrackEvent.TYPE_COUNTER:
            view.counters.setdefault(e.track_uuid, []).append((t, e.double_counter_value))
        elif e.type == TrackEvent.TYPE_SLICE_BEGIN:
            open_.setdefault(e.track_uuid, []).append((t, names.get(e.name_iid, e.name)))
        elif e.type == TrackEvent.TYPE_SLICE_END and open_.get(e.track_uuid):
            t0, name = open_[e.track_uuid].pop()
            view.slices.setdefault(e.track_uuid, []).append((t0, t, name))
        elif e.type == TrackEvent.TYPE_INSTANT:
            view.instants.setdefault(e.track_uuid, []).append((t, names.get(e.name_iid, e.name)))
    return view


_INSTANT_COLOURS = {"fault trip": "tab:red", "safe command": "tab:green", "deadline miss": "tab:red",
                    "overrun fault": "tab:red", "watchdog": "tab:gray", "injector": "tab:orange"}


def _colour(name: str) -> str:
    return next((c for k, c in _INSTANT_COLOURS.items() if name.startswith(k)), "tab:purple")


def _draw_span(ax, view: TraceView, rows: list[int], t0: float, t1: float) -> None:
    for y, uuid in enumerate(rows):
        if uuid in view.slices:
            bars = [(a, b - a) for a, b, _ in view.slices[uuid] if b >= t0 and a <= t1]
            colour = "tab:red" if view.tracks[uuid][0].startswith("ISR") else "tab:blue"
            ax.broken_barh([(a, max(w, (t1 - t0) / 800)) for a, w in bars], (y - 0.35, 0.7), color=colour, lw=0)
        for t, name in (e for e in view.instants.get(uuid, []) if t0 <= e[0] <= t1):
            ax.plot([t], [y], marker="v", ms=4, color=_colour(name), ls="")
        named = {}  # one label per kind of instant in the span: its first
        for t, name in view.instants.get(uuid, []):
            if t0 <= t <= t1 and not name.startswith("watchdog kick"):
                named.setdefault(name.split(":")[0], (t, name))
        for k, (t, name) in enumerate(named.values()):  # alternately above and below the marker
            ax.annotate(name, (t, y), xytext=(2, 4 if k % 2 == 0 else -9), textcoords="offset points", fontsize=5.5,
                        color=_colour(name))
        series = view.counters.get(uuid, [])
        before = [(t0, v) for t, v in series if t < t0][-1:]  # the value holding at the span's start
        samples = before + [(t, v) for t, v in series if t0 <= t <= t1]
        if samples:
            samples.append((t1, samples[-1][1]))  # and holding to its end
            lo, hi = min(v for _, v in samples), max(v for _, v in samples)
            scale = (hi - lo) or 1.0
            ax.step([t for t, _ in samples], [y - 0.4 + 0.8 * (v - lo) / scale for _, v in samples], where="post",
                    lw=0.7, color="tab:green")
            ax.text(1.0, y, f" {lo:.3g}..{hi:.3g}", transform=ax.get_yaxis_transform(), fontsize=5, va="center")
    ax.set_xlim(t0, t1)


def draw(view: TraceView, out: Path, window: tuple[float, float], zoom: tuple[float, float] | None = None,
         title: str = "") -> None:
    """Draw the tracks over ``window`` (and ``zoom`` beside it) into the PNG ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = view.rows()
    spans = [window] + ([zoom] if zoom is not None else [])
    fig, axes = plt.subplots(1, len(spans), sharey=True, figsize=(6.5 * len(spans), 0.24 * len(rows) + 1.2),
                             layout="constrained", squeeze=False)
    for ax, (t0, t1) in zip(axes[0], spans, strict=True):
        _draw_span(ax, view, rows, t0, t1)
        if ax is axes[0][0]:  # the rows share the y axis: the first track on top
            ax.invert_yaxis()
        ax.grid(axis="x", lw=0.3)
        ax.set_xlabel("time [s]" if t1 - t0 > 0.05 else f"time [s] (a {1e3 * (t1 - t0):.0f} ms zoom)")
        ax.tick_params(labelsize=7)
        if zoom is not None and ax is axes[0][0]:
            ax.axvspan(*zoom, color="tab:orange", alpha=0.15, lw=0)
    labels = []
    for uuid in rows:
        name, parent, _, _ = view.tracks[uuid]
        group = view.tracks[parent][0].split(" (")[0] if parent is not None else ""
        labels.append(f"{group}: {name}" if group else name)
    axes[0][0].set_yticks(range(len(rows)), labels, fontsize=6.5)
    if title:
        fig.suptitle(title, fontsize=8)
    fig.savefig(out, dpi=150)
    plt.close(fig)


def docs_figure(out: Path = DOCS_PNG) -> Path:
    """The picture of docs/telemetry.md: one stride of a 20 kg walk, a control overrun tripping the supervisor."""
    import logging
    import tempfile

    from firmware.config import load_firmware_config
    from hal.virtual.faults import make_injector
    from host_tools.commands.run import controller_for
    from host_tools.reports.report import TRACE_FILE, write_outputs
    from host_tools.runner import RunConfig, run_virtual

    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    fw = load_firmware_config().with_changes(controller="impedance", controller_params={})
    fault = make_injector("task_overrun", 1.4, 0.05, seed=3, factor=100.0, task="control")
    r = run_virtual(RunConfig(strides=1, seed=0, scenario="walk", body_mass_kg=20.0, firmware=fw,
                              controller=controller_for(fw, "walk", 20.0), faults=(fault,), duration_s=1.8))
    trip = r.firmware.supervisor.tripped_at_s
    assert trip is not None and r.gait_start_s is not None
    with tempfile.TemporaryDirectory() as tmp:
        write_outputs(r, Path(tmp), plot=False)
        view = read_view(Path(tmp) / TRACE_FILE)
    start = r.gait_start_s
    draw(view, out, (start, min(start + r.firmware.config.stride_s, r.sim_time_s)), (trip - 0.005, trip + 0.004),
         title=f"pafp run --scenario walk --body-mass 20, control task x100 from 1.4 s for 50 ms: "
               f"{r.firmware.supervisor.reason.name} at {trip:.4f} s (left: the stride; right: the trip)")
    return out


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m host_tools.reports.trace_figure", description=__doc__)
    parser.add_argument("trace", type=Path, nargs="?")
    parser.add_argument("out", type=Path, nargs="?")
    parser.add_argument("--window", type=float, nargs=2, metavar=("A", "B"))
    parser.add_argument("--zoom", type=float, nargs=2, metavar=("C", "D"))
    parser.add_argument("--docs", action="store_true", help=f"make {DOCS_PNG.relative_to(ROOT)} from a run")
    args = parser.parse_args(argv)
    if args.docs:
        print(docs_figure())
        return 0
    if args.trace is None or args.out is None or args.window is None:
        print("trace_figure: give TRACE OUT.png --window A B, or --docs", file=sys.stderr)
        return 2
    draw(read_view(args.trace), args.out, tuple(args.window), tuple(args.zoom) if args.zoom else None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
