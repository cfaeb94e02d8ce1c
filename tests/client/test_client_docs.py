"""The client's docstrings (quilting_client._docs): written once for both clients, every
option of the service's schema documented where ``**options`` passes it on."""

from __future__ import annotations

import pytest

from quilting_client import AsyncClient, Client
from quilting_client._docs import DOCSTRINGS, OPTIONS_OF
from quilting_client._options import schemas


@pytest.mark.parametrize("name", sorted(DOCSTRINGS))
def test_both_clients_carry_the_same_docstring(name: str) -> None:
    sync, both = getattr(Client, name).__doc__, getattr(AsyncClient, name).__doc__
    assert sync == both
    assert sync.startswith(DOCSTRINGS[name])


@pytest.mark.parametrize("name", sorted(OPTIONS_OF))
def test_every_option_of_the_operation_is_documented(name: str) -> None:
    doc = getattr(Client, name).__doc__
    options = schemas()[OPTIONS_OF[name]]
    assert "Other Parameters" in doc
    for option, schema in options.items():
        if option in ("width", "height"):
            continue
        assert f"\n{option} : " in doc, f"{name} does not document {option}"
        first = " ".join(schema["description"].split()[:5])
        assert first in " ".join(doc.split()), f"{name}: {option}'s description"


def test_every_method_taking_options_is_listed() -> None:
    import inspect

    takes = {
        name
        for name, member in inspect.getmembers(Client, inspect.isfunction)
        if any(p.kind is p.VAR_KEYWORD for p in inspect.signature(member).parameters.values())
    }
    assert takes == set(OPTIONS_OF)
