"""Server-sent events, without any I/O: the ``text/event-stream`` of a job decoded into events.

The drivers (the sync and async clients) only read text off the wire; :class:`LineSplitter`
cuts it into the stream's lines and :class:`EventReader` turns them into :class:`ServerEvent`
objects and decides when to stop reading, so that both clients read a stream the same way.
"""

from __future__ import annotations

import json
import re
import time
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ServerEvent:
    """One server-sent event: its name and its JSON data."""

    name: str
    data: dict[str, Any]


def _event_data(text: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except (ValueError, RecursionError):  # not JSON, or nested past the parser's depth
        return {"data": text}
    return value if isinstance(value, dict) else {"data": value}


#: The stream's line ends: CRLF, LF or CR, and no other (``str.splitlines`` would also cut at
#: U+2028, U+0085 and the like, which JSON may hold raw inside a string).
_LINE_END = re.compile(r"\r\n|\r|\n")


class LineSplitter:
    """The lines of a ``text/event-stream`` from its text in chunks cut anywhere.

    Lines end at CRLF, LF or CR only, a CRLF cut between two chunks included; a byte order
    mark at the start of the stream is dropped, as the WHATWG rules say.
    """

    def __init__(self) -> None:
        self._pending = ""
        self._after_cr = False  # the last chunk ended with CR: a LF next belongs to it
        self._started = False

    def feed(self, chunk: str) -> list[str]:
        """The lines that ``chunk`` completes, without their ends."""
        if not chunk:
            return []
        if not self._started:
            self._started = True
            chunk = chunk.removeprefix("\ufeff")
        if self._after_cr and chunk.startswith("\n"):
            chunk = chunk[1:]
        text = self._pending + chunk
        self._after_cr = text.endswith("\r")
        lines = _LINE_END.split(text)
        self._pending = lines.pop()
        return lines

    def close(self) -> list[str]:
        """At the end of the stream: its last line, if it had no line end."""
        pending, self._pending = self._pending, ""
        return [pending] if pending else []


class SSEDecoder:
    """Incremental decoder of a ``text/event-stream``, fed one line at a time.

    Follows the WHATWG rules that matter here: ``event:`` names the event, ``data:`` lines
    are joined with newlines, a blank line dispatches, ``:`` starts a comment. ``id:`` and
    ``retry:`` are ignored: after a broken stream the client asks for the job's status, which
    is complete, instead of resuming from an event id.
    """

    def __init__(self) -> None:
        self._name = ""
        self._data: list[str] = []

    def feed(self, line: str) -> ServerEvent | None:
        """Take one line (without its terminator); return the event it completes, if any."""
        if not line:
            return self._dispatch()
        if line.startswith(":"):
            return None
        name, colon, value = line.partition(":")
        if colon and value.startswith(" "):
            value = value[1:]
        if name == "event":
            self._name = value
        elif name == "data":
            self._data.append(value)
        return None

    def flush(self) -> ServerEvent | None:
        """At the end of the stream: the last event if the final blank line was missing.

        The standard drops such an event; keeping it is kinder to a terminal event written
        just before the connection closed.
        """
        return self._dispatch()

    def _dispatch(self) -> ServerEvent | None:
        name, data = self._name or "message", self._data
        self._name, self._data = "", []
        if not data:
            return None
        return ServerEvent(name, _event_data("\n".join(data)))


class EventReader:
    """The events of one open stream, from its lines, for at most ``limit`` seconds.

    A driver feeds it lines until :meth:`wants` says enough, then takes the outcome with
    :meth:`pop`; a stream that breaks (a reset, a read timeout) gives no event::

        while reader.wants(next(lines, None)):
            pass
        event = reader.pop()

    Parameters
    ----------
    limit : float or None
        Seconds the stream may be read for; None: as long as it lasts. Heartbeat comments
        alone must not keep a stream read past its limit, or a busy stream could outlast the
        caller's deadline.
    """

    def __init__(self, limit: float | None) -> None:
        self._until = None if limit is None else time.monotonic() + limit
        self._decoder = SSEDecoder()
        self._event: ServerEvent | None = None

    def wants(self, line: str | None) -> bool:
        """Take the next line (None: the stream ended); whether to read another.

        Reading stops at a complete event, at the end of the stream, and once the limit has
        passed.
        """
        if line is None:
            self._event = self._decoder.flush()
            return False
        self._event = self._decoder.feed(line)
        if self._event is not None:
            return False
        # Only comments for too long: stop, so that the flow checks the job and its deadline.
        return self._until is None or time.monotonic() < self._until

    def pop(self) -> ServerEvent | None:
        """The event that stopped the reading; None at the end, or when the limit passed."""
        event, self._event = self._event, None
        return event
