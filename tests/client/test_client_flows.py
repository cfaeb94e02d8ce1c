"""The sans-I/O flows (``quilting_client._flows``) driven by hand."""

from __future__ import annotations

import pytest
from client_fakes import (
    TEXTURE,
    TILED,
    tile_response,
)

from quilting_client import (
    QuiltingClientError,
)
from quilting_client import _flows as flows
from quilting_client import _protocol as proto


def test_tile_flow_sends_once_and_returns_the_png() -> None:
    flow = flows.tile(TEXTURE, axes="y", band=3, timeout=None, blend="poisson")
    action = next(flow)
    assert action == flows.Send(proto.tile_request(TEXTURE, axes="y", band=3, blend="poisson"))
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
