"""A Perfetto trace in its native protobuf format: tracks, slices, counters and instants, written in time order.

The packets are the ``perfetto`` package's ``TracePacket`` messages (its published schema), serialised one at a
time from a reused template per kind and framed as the ``packet`` field of a ``Trace`` (tag 1, length-delimited),
so the file is a ``Trace`` message that ui.perfetto.dev and trace_processor open. Event and argument names are
interned once (``InternedData`` in the first packet); timestamps are nanoseconds on the trace's default clock.

Each stream of events handed to :meth:`PerfettoTrace.write` is an iterable of ``(t_ns, packet bytes)`` in time
order (see :meth:`slice`, :meth:`begin`, :meth:`end`, :meth:`instant`, :meth:`counter`); the streams are merged by
time, so the whole trace is never in memory as messages. The file is written under a temporary name and renamed.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Iterable, Iterator
from pathlib import Path

from perfetto.protos.perfetto.trace.perfetto_trace_pb2 import (
    CounterDescriptor,
    TracePacket,
    TrackDescriptor,
    TrackEvent,
)

__all__ = ["PerfettoTrace", "Stream"]

SEQUENCE_ID = 1
Stream = Iterable[tuple[int, bytes]]
"""Packets of one kind in time order: (timestamp in ns, serialised TracePacket)."""


def _framed(packet: bytes) -> bytes:
    """The packet as one ``Trace.packet`` field: tag 0x0a, its length as a varint, the bytes."""
    n = len(packet)
    head = bytearray(b"\x0a")
    while n > 0x7F:
        head.append((n & 0x7F) | 0x80)
        n >>= 7
    head.append(n)
    return bytes(head) + packet


class PerfettoTrace:
    """Tracks and interned names of one trace; the event packets are made by its methods and streamed to write.

    >>> tr = PerfettoTrace()
    >>> cpu = tr.track("control")
    >>> stream = tr.slice(cpu, "control", 1000, 2500)
    >>> [t for t, _ in stream]
    [1000, 2500]
    """

    def __init__(self) -> None:
        """No tracks yet."""
        self._descriptors: list[TracePacket] = []
        self._names: dict[str, int] = {}
        self._arg_names: dict[str, int] = {}
        self._next_uuid = 1
        self._begins: dict[tuple[str, ...], TracePacket] = {}  # slice begins and instants, by their argument names
        self._instants: dict[tuple[str, ...], TracePacket] = {}
        self._slice_end = self._template(TrackEvent.TYPE_SLICE_END, 0)  # refers to no interned name
        self._counter = self._template(TrackEvent.TYPE_COUNTER, 0)

    @staticmethod
    def _template(kind: int, flags: int) -> TracePacket:
        p = TracePacket()
        p.trusted_packet_sequence_id = SEQUENCE_ID
        if flags:
            p.sequence_flags = flags
        p.track_event.type = kind
        return p

    def track(self, name: str, parent: int | None = None, *, unit: str | None = None, rank: int | None = None,
              ordered: bool = False) -> int:
        """A new track (a counter track when ``unit`` is given, e.g. "deg"); returns its uuid.

        ``parent`` groups it under another track; ``rank`` orders it among its siblings when the parent was made
        with ``ordered`` (else the UI sorts children by name).
        """
        uuid = self._next_uuid
        self._next_uuid += 1
        p = TracePacket()
        d = p.track_descriptor
        d.uuid = uuid
        d.name = name
        if parent is not None:
            d.parent_uuid = parent
        if ordered:
            d.child_ordering = TrackDescriptor.EXPLICIT
        if rank is not None:
            d.sibling_order_rank = rank
        if unit is not None:
            d.counter.unit_name = unit
            d.counter.unit = CounterDescriptor.UNIT_UNSPECIFIED
        self._descriptors.append(p)
        return uuid

    def _iid(self, table: dict[str, int], name: str) -> int:
        iid = table.get(name)
        if iid is None:
            iid = table[name] = len(table) + 1
        return iid

    def _with_args(self, templates: dict[tuple[str, ...], TracePacket], kind: int,
                   args: dict[str, object] | None) -> TracePacket:
        """The template packet of ``kind`` whose debug annotations are ``args`` (values set, names interned)."""
        keys = tuple(args) if args else ()
        p = templates.get(keys)
        if p is None:
            p = templates[keys] = self._template(kind, TracePacket.SEQ_NEEDS_INCREMENTAL_STATE)
            for key in keys:
                p.track_event.debug_annotations.add().name_iid = self._iid(self._arg_names, key)
        if args:
            for a, value in zip(p.track_event.debug_annotations, args.values(), strict=True):
                if isinstance(value, bool):
                    a.bool_value = value
                elif isinstance(value, int):
                    a.int_value = value
                elif isinstance(value, float):
                    a.double_value = value
                else:
                    a.string_value = str(value)
        return p

    def _named(self, templates: dict[tuple[str, ...], TracePacket], kind: int, track: int, name: str, t_ns: int,
               args: dict[str, object] | None) -> tuple[int, bytes]:
        """An event of ``kind`` that carries a name and arguments (a slice's begin or an instant)."""
        p = self._with_args(templates, kind, args)
        p.timestamp = t_ns
        e = p.track_event
        e.track_uuid = track
        e.name_iid = self._iid(self._names, name)
        return t_ns, p.SerializeToString()

    def begin(self, track: int, name: str, t_ns: int, args: dict[str, object] | None = None) -> tuple[int, bytes]:
        """A slice's start on ``track`` (ended by :meth:`end` on the same track)."""
        return self._named(self._begins, TrackEvent.TYPE_SLICE_BEGIN, track, name, t_ns, args)

    def slice(self, track: int, name: str, begin_ns: int, end_ns: int, args: dict[str, object] | None = None
              ) -> list[tuple[int, bytes]]:
        """A whole slice on ``track``: its begin and its end."""
        return [self.begin(track, name, begin_ns, args), self.end(track, end_ns)]

    def end(self, track: int, t_ns: int) -> tuple[int, bytes]:
        """The end of the innermost open slice on ``track``."""
        p = self._slice_end
        p.timestamp = t_ns
        p.track_event.track_uuid = track
        return t_ns, p.SerializeToString()

    def instant(self, track: int, name: str, t_ns: int, args: dict[str, object] | None = None) -> tuple[int, bytes]:
        """A zero-duration event on ``track``."""
        return self._named(self._instants, TrackEvent.TYPE_INSTANT, track, name, t_ns, args)

    def counter(self, track: int, t_ns: int, value: float) -> tuple[int, bytes]:
        """A counter track's value from ``t_ns`` on."""
        p = self._counter
        p.timestamp = t_ns
        e = p.track_event
        e.track_uuid = track
        e.double_counter_value = value
        return t_ns, p.SerializeToString()

    def _head(self) -> Iterator[bytes]:
        """The track descriptors, then the interned names (clearing the sequence's incremental state)."""
        for d in self._descriptors:
            yield d.SerializeToString()
        p = TracePacket()
        p.trusted_packet_sequence_id = SEQUENCE_ID
        p.sequence_flags = TracePacket.SEQ_INCREMENTAL_STATE_CLEARED
        for name, iid in self._names.items():
            e = p.interned_data.event_names.add()
            e.iid, e.name = iid, name
        for name, iid in self._arg_names.items():
            a = p.interned_data.debug_annotation_names.add()
            a.iid, a.name = iid, name
        yield p.SerializeToString()

    def write(self, path: str | Path, streams: Iterable[Stream]) -> int:
        """Write the trace to ``path`` (atomically): the head, then every stream's packets merged by time.

        The streams are consumed first (packets are made as they are iterated, which interns their names), so a
        stream must not be a one-pass iterator that the caller needs again. Returns the bytes written.
        """
        path = Path(path)
        made = [s if isinstance(s, list) else list(s) for s in streams]  # every name interned before the head
        merged = heapq.merge(*made, key=lambda tp: tp[0])
        tmp = path.with_name(f".{path.name}.tmp")
        size = 0
        try:
            with tmp.open("wb") as f:
                for packet in self._head():
                    size += f.write(_framed(packet))
                while chunk := list(itertools.islice(merged, 20_000)):
                    size += f.write(b"".join([_framed(b) for _, b in chunk]))
            tmp.replace(path)
        except BaseException:  # a failed write leaves no partial file behind
            tmp.unlink(missing_ok=True)
            raise
        return size
