"""The sans-I/O flows (``quilting_client._flows``) driven by hand, and the pieces the two
drivers share (``_actions.Steps``, ``_events.EventReader``)."""

from __future__ import annotations

import pytest
from client_fakes import (
    TEXTURE,
    TILED,
    tile_response,
)

from quilting_client import (
    ConnectionFailedError,
    QuiltingClientError,
)
from quilting_client import _actions as actions
from quilting_client import _flows as flows
from quilting_client import _protocol as proto
from quilting_client._events import EventReader, ServerEvent


def test_tile_flow_sends_once_and_returns_the_png() -> None:
    flow = flows.tile(TEXTURE, axes="y", band=3, timeout=None, blend="poisson")
    action = next(flow)
    assert action == actions.Send(proto.tile_request(TEXTURE, axes="y", band=3, blend="poisson"))
    with pytest.raises(StopIteration) as stop:
        flow.send(tile_response(TILED))
    assert stop.value.value == TILED


def test_tile_flow_rejects_an_answer_that_is_not_a_png() -> None:
    flow = flows.tile(TEXTURE, axes="both", band=None, timeout=None)
    next(flow)
    with pytest.raises(QuiltingClientError) as caught:
        flow.send(tile_response(b'{"status": "queued"}', "application/json"))
    assert caught.value.code == "invalid_response" and "/tile" in str(caught.value)


@pytest.mark.parametrize("timeout", [0.0, -1.0])
def test_tile_flow_rejects_a_timeout_that_is_not_positive(timeout: float) -> None:
    with pytest.raises(ValueError, match="timeout must be positive"):
        next(flows.tile(TEXTURE, axes="both", band=None, timeout=timeout))


def test_steps_throw_a_failed_action_s_error_into_the_flow() -> None:
    performed = []
    with actions.Steps(flows.health()) as steps:
        for action in steps:
            performed.append(action)
            with steps.catching():
                raise ConnectionFailedError("refused", code="connection_failed")
    # The flow handled the error: health() says False rather than raising.
    assert performed == [actions.Send(proto.health_request())] and steps.result is False


def test_steps_let_an_error_the_flow_does_not_handle_through() -> None:
    flow = flows.tile(TEXTURE, axes="both", band=None, timeout=None)
    with pytest.raises(ConnectionFailedError, match="reset"), actions.Steps(flow) as steps:
        for _ in steps:
            with steps.catching():
                raise ConnectionFailedError("reset", code="connection_failed")


def test_event_reader_stops_at_an_event_at_the_end_and_past_its_limit() -> None:
    reader = EventReader(None)
    lines = iter([": hello", "event: progress", 'data: {"progress": 0.5}', "", "data: 1"])
    while reader.wants(next(lines, None)):
        pass
    assert reader.pop() == ServerEvent("progress", {"progress": 0.5})
    # A last event without its blank line is kept at the end of the stream.
    while reader.wants(next(lines, None)):
        pass
    assert reader.pop() == ServerEvent("message", {"data": 1})
    # Comments alone do not keep a stream read past its limit.
    expired = EventReader(0.0)
    assert not expired.wants(": heartbeat") and expired.pop() is None
