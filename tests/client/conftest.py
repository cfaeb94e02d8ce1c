"""The client tests' fixtures: ``connect`` (a ``Client`` and an ``AsyncClient`` in turn,
talking to a fake service) and ``fake_cli`` (the command line's client on a fake)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest
from client_fakes import (
    BASE,
    AsyncAdapter,
    FakeService,
)

from quilting_client import (
    AsyncClient,
    Client,
    cli,
)


@pytest.fixture(params=["sync", "async"])
def connect(request: pytest.FixtureRequest) -> Iterator[Callable[..., Any]]:
    """``connect(service, api_key=None, real_sleep=False)`` -> a client; ``.sleeps`` records."""
    opened: list[Any] = []

    def make(service: FakeService, api_key: str | None = None, real_sleep: bool = False) -> Any:
        transport = httpx.MockTransport(service)
        sleeps: list[float] = []
        client: Any
        if request.param == "sync":
            client = Client(BASE, api_key, transport=transport)
            if not real_sleep:
                client._sleep = sleeps.append
            wrapped: Any = client
        else:
            client = AsyncClient(BASE, api_key, transport=transport)
            if not real_sleep:

                async def record(seconds: float) -> None:
                    sleeps.append(seconds)

                client._sleep = record
            wrapped = AsyncAdapter(client)
        wrapped.sleeps = sleeps
        opened.append(wrapped)
        return wrapped

    yield make
    for client in opened:
        client.close()


@pytest.fixture
def fake_cli(monkeypatch: pytest.MonkeyPatch) -> FakeService:
    """The CLI's client talks to a fake service; the factory's arguments are recorded."""
    service = FakeService()
    service.factory_calls = []  # type: ignore[attr-defined]

    def make_client(server: str, api_key: str | None) -> Client:
        service.factory_calls.append((server, api_key))  # type: ignore[attr-defined]
        return Client(server, api_key, transport=httpx.MockTransport(service))

    monkeypatch.setattr(cli, "make_client", make_client)
    monkeypatch.delenv("QUILTING_SERVER", raising=False)
    monkeypatch.delenv("QUILTING_URL", raising=False)
    monkeypatch.delenv("QUILTING_API_KEY", raising=False)
    return service
