"""Server-sent events (``quilting_client._events``): the decoder, the reader and the streams.

Covers
------
- :class:`SSEDecoder` against the rules its docstring takes from the WHATWG event-stream
  format: ``data:`` with and without its one optional space, several ``data`` lines joined
  with newlines, ``event:`` naming the event (``message`` by default, reset at each dispatch),
  comments and unknown fields (``id``, ``retry`` included) ignored, a block without data not
  dispatched, the last event kept at the end of the stream without its blank line (documented
  as kinder than the standard);
- the JSON of an event: an object as it is, any other JSON value or text that is not JSON
  wrapped as ``{"data": value}``;
- :class:`EventReader` and its limit, on a fake monotonic clock: lines are read until the
  limit has passed (comments or a partial event alike), never past it, and forever without
  one;
- the drivers' streams (``_sync._EventStream`` and ``_async._AsyncEventStream``) reading the
  bytes of a response: a sample stream cut at every byte (and in single bytes) gives the same
  events, CRLF, CR and LF line ends are the same, a stream that breaks mid-event gives None,
  and a busy stream stops at its limit.

Nothing sleeps: the clocks are fakes and the streams are in memory.
"""

from __future__ import annotations

import asyncio
import json
import random
from collections.abc import AsyncIterator, Iterator, Sequence
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from client_fakes import FakeClock

from quilting_client import _events as events_module
from quilting_client._async import _AsyncEventStream
from quilting_client._events import EventReader, ServerEvent, SSEDecoder
from quilting_client._sync import _EventStream


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    """The clock of ``_events`` (the readers' limits), replaced by a fake one."""
    fake = FakeClock()
    monkeypatch.setattr(events_module, "time", SimpleNamespace(monotonic=fake.monotonic))
    return fake


def decode(lines: Sequence[str], *, flush: bool = True) -> list[ServerEvent]:
    """The events a fresh decoder gives for ``lines`` (then the end of the stream)."""
    decoder = SSEDecoder()
    found = [event for line in lines if (event := decoder.feed(line)) is not None]
    if flush and (last := decoder.flush()) is not None:
        found.append(last)
    return found


# -- SSEDecoder: the fields -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "payload"),
    [
        ("data: 7", 7),
        ("data:7", 7),  # the space is optional
        ("data:  7", 7),  # only one space is taken off; JSON ignores the other
        ('data:  "x"', "x"),
        ("data:   text", "  text"),  # not JSON: kept with the spaces past the first
        ("data:", ""),  # an empty data line still makes an event
        ("data", ""),  # a field name without colon: the whole line is the name
    ],
)
def test_a_data_line_loses_one_leading_space_at_most(line: str, payload: object) -> None:
    assert decode([line, ""], flush=False) == [ServerEvent("message", {"data": payload})]


def test_several_data_lines_are_joined_with_newlines() -> None:
    lines = ['data: {"progress":', "data: 0.5,", 'data:"stage": "a"}', ""]
    assert decode(lines) == [ServerEvent("message", {"progress": 0.5, "stage": "a"})]
    assert decode(["data: one", "data:", "data: three", ""]) == [
        ServerEvent("message", {"data": "one\n\nthree"})
    ]


def test_event_names_the_event_and_the_last_name_wins() -> None:
    assert decode(["event: first", "event: progress", "data: {}", ""]) == [
        ServerEvent("progress", {})
    ]
    assert decode(["event:done", "data: {}", ""]) == [ServerEvent("done", {})]
    # An empty name is the default one.
    assert decode(["event:", "data: {}", ""]) == [ServerEvent("message", {})]


def test_the_name_is_reset_after_each_dispatch_even_without_data() -> None:
    lines = ["event: progress", "data: 1", "", "data: 2", "", "event: lost", "", "data: 3", ""]
    assert decode(lines) == [
        ServerEvent("progress", {"data": 1}),
        ServerEvent("message", {"data": 2}),
        ServerEvent("message", {"data": 3}),
    ]


def test_comments_are_ignored_wherever_they_are() -> None:
    lines = [": connected", "event: progress", ":", ": data: 9", "data: 1", ": heartbeat", ""]
    assert decode(lines) == [ServerEvent("progress", {"data": 1})]


def test_a_block_without_data_is_not_dispatched() -> None:
    decoder = SSEDecoder()
    for line in ["retry: 3000", "id: 5", "event: progress", ":comment"]:
        assert decoder.feed(line) is None
    assert decoder.feed("") is None
    assert decoder.feed("") is None
    assert decoder.flush() is None


@pytest.mark.parametrize(
    "field",
    ["id: 41", "id", "retry: 3000", "retry: soon", "foo: bar", "Data: 8", "data : 8", " data: 8"],
)
def test_unknown_fields_and_id_and_retry_change_nothing(field: str) -> None:
    plain = decode(["event: progress", "data: 1", ""])
    assert decode(["event: progress", field, "data: 1", field, ""]) == plain
    assert plain == [ServerEvent("progress", {"data": 1})]


def test_the_last_event_without_its_blank_line_is_kept_at_the_end() -> None:
    decoder = SSEDecoder()
    assert decoder.feed("event: done") is None
    assert decoder.feed('data: {"id": "j1"}') is None
    assert decoder.flush() == ServerEvent("done", {"id": "j1"})
    # Flushing again, or after a complete event, gives nothing more.
    assert decoder.flush() is None
    assert decoder.feed("data: 1") is None
    assert decoder.feed("") == ServerEvent("message", {"data": 1})
    assert decoder.flush() is None


def test_the_decoder_goes_on_after_a_flush() -> None:
    decoder = SSEDecoder()
    decoder.feed("event: stale")
    assert decoder.flush() is None  # a name alone is no event, and it is forgotten
    assert decoder.feed("data: 2") is None
    assert decoder.feed("") == ServerEvent("message", {"data": 2})


# -- SSEDecoder: the JSON of an event ----------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "data"),
    [
        ('{"progress": 0.5, "stage": "quilting"}', {"progress": 0.5, "stage": "quilting"}),
        ('{"data": [1]}', {"data": [1]}),  # an object is never wrapped, even one like that
        ("[1, 2]", {"data": [1, 2]}),
        ('"done"', {"data": "done"}),
        ("null", {"data": None}),
        ("true", {"data": True}),
        ("2.5", {"data": 2.5}),
        ('{"progress": 0.5', {"data": '{"progress": 0.5'}),  # cut short: kept as text
        ("not json", {"data": "not json"}),
        ("{'single': 1}", {"data": "{'single': 1}"}),
    ],
)
def test_data_that_is_not_a_json_object_is_wrapped(text: str, data: dict[str, Any]) -> None:
    assert decode([f"data: {text}", ""]) == [ServerEvent("message", data)]


# -- EventReader: when to stop ------------------------------------------------------------------


def read(reader: EventReader, lines: Iterator[str]) -> ServerEvent | None:
    while reader.wants(next(lines, None)):
        pass
    return reader.pop()


def test_a_reader_takes_one_event_at_a_time_and_pop_empties_it() -> None:
    lines = iter(["event: progress", "data: 1", "", "data: 2", "", ": bye"])
    reader = EventReader(None)
    assert read(reader, lines) == ServerEvent("progress", {"data": 1})
    assert reader.pop() is None
    assert read(reader, lines) == ServerEvent("message", {"data": 2})
    assert read(reader, lines) is None  # a comment, then the end
    assert not reader.wants(None) and reader.pop() is None


def test_without_limit_a_reader_reads_comments_for_ever(clock: FakeClock) -> None:
    reader = EventReader(None)
    for step in range(50):
        clock.now += 1e6 * step
        assert reader.wants(": heartbeat")
    assert reader.pop() is None


@pytest.mark.parametrize("line", [": heartbeat", "data: part of an event", "event: progress"])
def test_a_reader_stops_once_its_limit_has_passed(clock: FakeClock, line: str) -> None:
    reader = EventReader(5.0)  # from 100.0 to 105.0 on the fake clock
    for now in (100.0, 102.0, 104.999):
        clock.now = now
        assert reader.wants(line), now
    clock.now = 105.0
    assert not reader.wants(line)
    assert reader.pop() is None


def test_a_reader_s_limit_counts_from_its_creation(clock: FakeClock) -> None:
    clock.now = 0.0
    early = EventReader(3.0)
    clock.now = 2.0
    late = EventReader(3.0)
    clock.now = 4.0
    assert not early.wants(": ping")
    assert late.wants(": ping")


def test_an_event_completed_within_the_limit_is_returned(clock: FakeClock) -> None:
    reader = EventReader(1.0)
    assert reader.wants("event: progress")
    clock.now += 0.5
    assert reader.wants("data: 1")
    assert not reader.wants("")
    assert reader.pop() == ServerEvent("progress", {"data": 1})


# -- the drivers' streams: bytes in, events out ----------------------------------------------------


class Chunks(httpx.SyncByteStream, httpx.AsyncByteStream):
    """A response body in given chunks; optionally an error after them, and a clock that each
    chunk moves on."""

    def __init__(
        self,
        chunks: Sequence[bytes],
        error: Exception | None = None,
        clock: FakeClock | None = None,
        seconds_per_chunk: float = 0.0,
    ) -> None:
        self.chunks = list(chunks)
        self.error = error
        self.clock = clock
        self.seconds_per_chunk = seconds_per_chunk
        self.sent = 0

    def _next_chunks(self) -> Iterator[bytes]:
        for chunk in self.chunks:
            if self.clock is not None:
                self.clock.now += self.seconds_per_chunk
            self.sent += 1
            yield chunk
        if self.error is not None:
            raise self.error

    def __iter__(self) -> Iterator[bytes]:
        yield from self._next_chunks()

    async def __aiter__(self) -> AsyncIterator[bytes]:
        for chunk in self._next_chunks():
            yield chunk


def response(body: httpx.SyncByteStream | httpx.AsyncByteStream) -> httpx.Response:
    return httpx.Response(200, stream=body, headers={"Content-Type": "text/event-stream"})


def read_sync(body: Chunks, limit: float | None = None) -> list[ServerEvent]:
    stream = _EventStream(response(body), limit)
    found = []
    while (event := stream.next()) is not None:
        found.append(event)
    stream.close()
    return found


async def read_async(body: Chunks, limit: float | None = None) -> list[ServerEvent]:
    stream = _AsyncEventStream(response(body), limit)
    found = []
    while (event := await stream.next()) is not None:
        found.append(event)
    await stream.aclose()
    return found


#: A stream with every kind of line: CRLF, CR and LF ends, comments, ``retry`` and ``id``, a
#: JSON object over two data lines (one without its space), text in UTF-8 of 2 and 3 bytes a
#: character, a block without data, an unknown field, and a last event without blank line.
SAMPLE = (
    b": connected\r\n"
    b"retry: 3000\r\n\r\n"
    b'id: 1\nevent: progress\ndata: {"progress": 0.25,\n'
    b'data:"stage": "t\xc3\xa9l\xc3\xa9\xe2\x82\xac"}\n\n'
    b"event: ignored\rfoo: bar\r\r"
    b"data: plain text\r\n: heartbeat\r\ndata:  two spaces\r\n\r\n"
    b"event: done\r"
    b'data: {"id": "j1"}'
)
SAMPLE_EVENTS = [
    ServerEvent("progress", {"progress": 0.25, "stage": "télé€"}),
    ServerEvent("message", {"data": "plain text\n two spaces"}),
    ServerEvent("done", {"id": "j1"}),
]


def splits(data: bytes) -> list[list[bytes]]:
    """``data`` cut in two at every byte, in single bytes, and in three at random places."""
    cuts = [[data[:i], data[i:]] for i in range(len(data) + 1)]
    cuts.append([data[i : i + 1] for i in range(len(data))])
    rng = random.Random(20240607)
    for _ in range(100):
        i, j = sorted(rng.sample(range(len(data) + 1), 2))
        cuts.append([data[:i], data[i:j], data[j:]])
    return [[chunk for chunk in cut if chunk] for cut in cuts]


def test_the_sample_stream_gives_its_events_whole() -> None:
    assert read_sync(Chunks([SAMPLE])) == SAMPLE_EVENTS


def test_the_sync_stream_gives_the_same_events_wherever_the_chunks_end() -> None:
    wrong = {
        tuple(map(len, cut)) for cut in splits(SAMPLE) if read_sync(Chunks(cut)) != SAMPLE_EVENTS
    }
    assert not wrong


def test_the_async_stream_gives_the_same_events_wherever_the_chunks_end() -> None:
    async def check() -> set[tuple[int, ...]]:
        wrong = set()
        for cut in splits(SAMPLE):
            if await read_async(Chunks(cut)) != SAMPLE_EVENTS:
                wrong.add(tuple(map(len, cut)))
        return wrong

    assert not asyncio.run(check())


STREAM = (
    ": connected\n\n"
    "retry: 3000\n\n"
    'id: 7\nevent: progress\ndata: {"progress": 0.5,\ndata: "stage": "quilting"}\n\n'
    'event: done\ndata: {"id": "j1"}\n\n'
)
STREAM_EVENTS = [
    ServerEvent("progress", {"progress": 0.5, "stage": "quilting"}),
    ServerEvent("done", {"id": "j1"}),
]


@pytest.mark.parametrize("end", ["\n", "\r\n", "\r"])
def test_crlf_cr_and_lf_line_ends_give_the_same_events(end: str) -> None:
    data = STREAM.replace("\n", end).encode()
    assert read_sync(Chunks([data])) == STREAM_EVENTS
    # Cut between the CR and the LF of each line end too.
    assert read_sync(Chunks([data[i : i + 1] for i in range(len(data))])) == STREAM_EVENTS
    assert asyncio.run(read_async(Chunks([data]))) == STREAM_EVENTS


@pytest.mark.parametrize("mark", ["\u2028", "\u2029", "\x85", "\x0b", "\x0c", "\x1c"])
def test_only_cr_and_lf_end_a_line(mark: str) -> None:
    # JSON may hold these raw inside a string; str.splitlines (httpx's iter_lines) cut there.
    text = f'{{"stage": "a{mark}b", "progress": 0.5}}'
    data = f"event: progress\ndata: {text}\n\n".encode()
    # JSON takes U+2028, U+2029 and U+0085 raw, not the C0 controls: those come as text, whole.
    payload = json.loads(text) if mark in "\u2028\u2029\x85" else {"data": text}
    expected = [ServerEvent("progress", payload)]
    for chunks in ([data], [data[i : i + 1] for i in range(len(data))]):
        assert read_sync(Chunks(chunks)) == expected
        assert asyncio.run(read_async(Chunks(chunks))) == expected


def test_a_byte_order_mark_at_the_start_is_dropped() -> None:
    data = b'\xef\xbb\xbfevent: done\ndata: {"id": "j1"}\n\n'
    expected = [ServerEvent("done", {"id": "j1"})]
    assert read_sync(Chunks([data])) == expected
    assert read_sync(Chunks([data[:2], data[2:]])) == expected  # a BOM cut in two
    assert asyncio.run(read_async(Chunks([data]))) == expected


def test_data_nested_past_the_parser_s_depth_is_kept_as_text() -> None:
    text = "[" * 100_000
    assert decode([f"data: {text}", ""]) == [ServerEvent("message", {"data": text})]


@pytest.mark.parametrize(
    "tail", [b'data: {"id": "j1"}', b'data: {"id": "j1"}\n', b'data: {"id": "j1"}\r']
)
def test_a_stream_that_ends_without_its_blank_line_keeps_its_last_event(tail: bytes) -> None:
    body = b"event: done\n" + tail
    expected = [ServerEvent("done", {"id": "j1"})]
    assert read_sync(Chunks([body])) == expected
    assert asyncio.run(read_async(Chunks([body]))) == expected


@pytest.mark.parametrize(
    "error",
    [httpx.ReadError("reset"), httpx.ReadTimeout("silent"), httpx.RemoteProtocolError("cut")],
)
def test_a_stream_that_breaks_mid_event_gives_none(error: Exception) -> None:
    chunks = [b"event: progress\ndata: 1\n\n", b"event: done\ndata: {"]
    # The event cut off by the failure is not made up from its first half.
    assert read_sync(Chunks(chunks, error)) == [ServerEvent("progress", {"data": 1})]
    assert asyncio.run(read_async(Chunks(chunks, error))) == [ServerEvent("progress", {"data": 1})]


def test_other_errors_of_a_stream_are_not_taken_for_its_end() -> None:
    with pytest.raises(ZeroDivisionError):
        read_sync(Chunks([b"data: 1\n"], ZeroDivisionError()))


@pytest.mark.parametrize("line", [b": heartbeat\n", b"data: 1\n"])
def test_a_busy_stream_is_read_up_to_its_limit_only(clock: FakeClock, line: bytes) -> None:
    # A line every second, for an hour; the limit is 10 s.
    body = Chunks([line] * 3600, clock=clock, seconds_per_chunk=1.0)
    assert read_sync(body, limit=10.0) == []
    assert body.sent == 10
    clock.now = 100.0
    body = Chunks([line] * 3600, clock=clock, seconds_per_chunk=1.0)
    assert asyncio.run(read_async(body, limit=10.0)) == []
    assert body.sent == 10


def test_a_stream_without_limit_is_read_to_its_end(clock: FakeClock) -> None:
    body = Chunks([b": heartbeat\n"] * 500 + [b"data: 1\n\n"], clock=clock, seconds_per_chunk=60.0)
    assert read_sync(body) == [ServerEvent("message", {"data": 1})]
    assert body.sent == 501


def test_the_service_s_own_stream_reads_as_its_events() -> None:
    # As quilting.service.events.job_stream writes it: a retry block, progress, the end.
    progress = {"progress": 0.5, "stage": "quilting", "status": "running"}
    final = {"id": "j1", "status": "done", "progress": 1.0}
    text = (
        "retry: 2000\n\n"
        f"id: 12\nevent: progress\ndata: {json.dumps(progress)}\n\n"
        f"id: 9999\nevent: done\ndata: {json.dumps(final)}\n\n"
    )
    assert read_sync(Chunks([text.encode()])) == [
        ServerEvent("progress", progress),
        ServerEvent("done", final),
    ]
