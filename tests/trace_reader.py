"""An independent reader of a Perfetto protobuf trace for the tests: the perfetto package's schema, protobuf's parser.

It shares nothing with pafp's writer (host_tools/reports/perfetto_trace.py): it parses the file as a ``Trace``
message, resolves the interned names of the sequence as trace_processor does (``SEQ_INCREMENTAL_STATE_CLEARED``
starts them, a packet that needs them must come after), and pairs each track's slice begins and ends as a stack.
It refuses what the Perfetto importer would reject or misdraw: an end without a begin, a slice left open, a
packet before its sequence's state, an event on a track never described, timestamps going back on a track.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from perfetto.protos.perfetto.trace.perfetto_trace_pb2 import Trace, TracePacket, TrackEvent


@dataclass
class Track:
    uuid: int
    name: str
    parent: int | None
    counter: bool
    unit: str
    rank: int | None


@dataclass
class Slice:
    track: int
    name: str
    ts: int
    dur: int
    depth: int
    args: dict


@dataclass
class Read:
    tracks: dict[int, Track] = field(default_factory=dict)
    slices: list[Slice] = field(default_factory=list)
    instants: list[Slice] = field(default_factory=list)
    counters: dict[int, list[tuple[int, float]]] = field(default_factory=dict)

    def track_named(self, name: str) -> Track:
        found = [t for t in self.tracks.values() if t.name == name]
        assert len(found) == 1, f"{len(found)} tracks named {name!r}: {[t.name for t in self.tracks.values()]}"
        return found[0]

    def on(self, name: str) -> list[Slice]:
        uuid = self.track_named(name).uuid
        return [s for s in self.slices if s.track == uuid]

    def instants_on(self, name: str) -> list[Slice]:
        uuid = self.track_named(name).uuid
        return [s for s in self.instants if s.track == uuid]

    def counter(self, name: str) -> list[tuple[int, float]]:
        return self.counters.get(self.track_named(name).uuid, [])


def _value(a) -> object:
    kind = a.WhichOneof("value")
    return getattr(a, kind) if kind else None


def read_trace(path: Path) -> Read:
    trace = Trace.FromString(Path(path).read_bytes())
    out = Read()
    names: dict[int, str] | None = None
    arg_names: dict[int, str] = {}
    open_: dict[int, list[tuple[int, str, dict]]] = {}
    last_ts: dict[int, int] = {}
    for p in trace.packet:
        if p.HasField("track_descriptor"):
            d = p.track_descriptor
            assert d.uuid not in out.tracks, f"track {d.uuid} described twice"
            out.tracks[d.uuid] = Track(d.uuid, d.name, d.parent_uuid if d.HasField("parent_uuid") else None,
                                       d.HasField("counter"), d.counter.unit_name,
                                       d.sibling_order_rank if d.HasField("sibling_order_rank") else None)
            continue
        if p.sequence_flags & TracePacket.SEQ_INCREMENTAL_STATE_CLEARED:
            names, arg_names = {}, {}
        if p.HasField("interned_data"):
            assert names is not None, "interned data before the sequence's state was cleared"
            names.update({e.iid: e.name for e in p.interned_data.event_names})
            arg_names.update({e.iid: e.name for e in p.interned_data.debug_annotation_names})
        if not p.HasField("track_event"):
            continue
        e = p.track_event
        assert e.track_uuid in out.tracks, f"event on undescribed track {e.track_uuid}"
        assert p.timestamp >= last_ts.get(e.track_uuid, 0), f"time goes back on track {e.track_uuid}"
        last_ts[e.track_uuid] = p.timestamp
        if e.type == TrackEvent.TYPE_COUNTER:
            out.counters.setdefault(e.track_uuid, []).append((p.timestamp, e.double_counter_value))
            continue
        if e.type != TrackEvent.TYPE_SLICE_END:
            assert p.sequence_flags & TracePacket.SEQ_NEEDS_INCREMENTAL_STATE and names is not None
            name = names[e.name_iid] if e.HasField("name_iid") else e.name
            args = {arg_names[a.name_iid]: _value(a) for a in e.debug_annotations}
        if e.type == TrackEvent.TYPE_SLICE_BEGIN:
            open_.setdefault(e.track_uuid, []).append((p.timestamp, name, args))
        elif e.type == TrackEvent.TYPE_SLICE_END:
            stack = open_.get(e.track_uuid)
            assert stack, f"slice end without a begin on track {e.track_uuid} at {p.timestamp}"
            ts, name, args = stack.pop()
            out.slices.append(Slice(e.track_uuid, name, ts, p.timestamp - ts, len(stack), args))
        elif e.type == TrackEvent.TYPE_INSTANT:
            out.instants.append(Slice(e.track_uuid, name, p.timestamp, 0, 0, args))
        else:
            raise AssertionError(f"unexpected event type {e.type}")
    left = {t: s for t, s in open_.items() if s}
    assert not left, f"slices left open: {left}"
    return out
