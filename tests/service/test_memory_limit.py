"""Unit tests of :mod:`quilting.service.memory_limit`.

Covers :func:`limit_memory` (the RLIMIT_DATA soft limit set to the VmData in use plus the
budget, a budget of 0 included; never above the hard limit, which is left as it was; nothing
limited, with a warning, where ``/proc/self/status`` cannot be read), the ``/proc/self/status``
reader behind it (kB lines in bytes, a missing or malformed line is None), and
:func:`describe_bytes`. The limits are faked in-process; one test sets them for real, in a
child process, since they cannot be raised again once lowered.
"""

from __future__ import annotations

import io
import logging
import os
import resource
import subprocess
import sys
import textwrap
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest

from quilting.service import memory_limit
from quilting.service.memory_limit import GiB, MiB, describe_bytes, limit_memory


class FakeResource(SimpleNamespace):
    """The ``resource`` module's limits, faked: a hard limit, and each limit set."""

    def __init__(self, hard: int) -> None:
        super().__init__(RLIMIT_DATA=resource.RLIMIT_DATA, RLIM_INFINITY=resource.RLIM_INFINITY)
        self.soft = resource.RLIM_INFINITY
        self.hard = hard
        self.set: list[tuple[int, tuple[int, int]]] = []

    def getrlimit(self, which: int) -> tuple[int, int]:
        assert which == resource.RLIMIT_DATA
        return self.soft, self.hard

    def setrlimit(self, which: int, limits: tuple[int, int]) -> None:
        self.set.append((which, limits))


def fake_limits(
    monkeypatch: pytest.MonkeyPatch, used: int | None, hard: int = resource.RLIM_INFINITY
) -> FakeResource:
    """VmData reads ``used``; the limits are a :class:`FakeResource` with ``hard``."""
    fake = FakeResource(hard)
    monkeypatch.setattr(memory_limit, "resource", fake)
    monkeypatch.setattr(memory_limit, "_status_bytes", lambda field: {"VmData": used}[field])
    return fake


@pytest.mark.parametrize("budget", [0, 1, 64 * MiB, 3 * GiB])
def test_the_cap_is_the_data_in_use_plus_the_budget(
    monkeypatch: pytest.MonkeyPatch, budget: int
) -> None:
    fake = fake_limits(monkeypatch, used=300 * MiB)
    assert limit_memory(budget) == 300 * MiB + budget
    assert fake.set == [(resource.RLIMIT_DATA, (300 * MiB + budget, resource.RLIM_INFINITY))]


@pytest.mark.parametrize(
    ("hard", "cap"),
    [(340 * MiB, 340 * MiB), (364 * MiB, 364 * MiB), (365 * MiB, 364 * MiB)],
    ids=["below", "equal", "above"],
)
def test_the_cap_never_passes_the_hard_limit(
    monkeypatch: pytest.MonkeyPatch, hard: int, cap: int
) -> None:
    fake = fake_limits(monkeypatch, used=300 * MiB, hard=hard)
    assert limit_memory(64 * MiB) == cap
    assert fake.set == [(resource.RLIMIT_DATA, (cap, hard))]  # the hard limit as it was


def unreadable(*args: Any, **kwargs: Any) -> Any:
    raise PermissionError("/proc/self/status")


def test_nothing_is_limited_where_the_status_file_cannot_be_read(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    fake = FakeResource(resource.RLIM_INFINITY)
    monkeypatch.setattr(memory_limit, "resource", fake)
    monkeypatch.setattr(memory_limit, "open", unreadable, raising=False)
    with caplog.at_level(logging.WARNING, logger="quilting.service"):
        assert limit_memory(64 * MiB) is None
    assert fake.set == []
    assert "not limited" in caplog.text


STATUS = "Name:\tpython\nVmPeak:\t  912340 kB\nVmSize:\t  900000 kB\nVmData:\t  123456 kB\n"


def status_file(text: str) -> Callable[..., io.StringIO]:
    def opened(path: str, *args: Any, **kwargs: Any) -> io.StringIO:
        assert path == "/proc/self/status"
        return io.StringIO(text)

    return opened


@pytest.mark.parametrize(
    ("text", "field", "expected"),
    [
        (STATUS, "VmData", 123456 * 1024),
        (STATUS, "VmSize", 900000 * 1024),
        (STATUS, "VmRSS", None),  # no such line
        (STATUS, "Vm", None),  # a prefix of fields, not a field
        ("VmData:\tlots kB\n", "VmData", None),
        ("VmData:\n", "VmData", None),
        ("", "VmData", None),
    ],
    ids=["data", "size", "missing", "prefix", "not-a-number", "no-value", "empty"],
)
def test_status_lines_are_read_in_bytes(
    monkeypatch: pytest.MonkeyPatch, text: str, field: str, expected: int | None
) -> None:
    monkeypatch.setattr(memory_limit, "open", status_file(text), raising=False)
    assert memory_limit._status_bytes(field) == expected


def test_a_malformed_status_file_limits_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = FakeResource(resource.RLIM_INFINITY)
    monkeypatch.setattr(memory_limit, "resource", fake)
    monkeypatch.setattr(memory_limit, "open", status_file("VmData:\t?? kB\n"), raising=False)
    assert limit_memory(MiB) is None
    assert fake.set == []


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="no /proc (not Linux)")
def test_the_real_limit_is_set_on_this_process_only_and_it_goes_on() -> None:
    """In a child: the soft limit becomes the cap, the hard one stays, and an allocation past
    the cap is a MemoryError the process survives; a lowered hard limit bounds the cap."""
    script = textwrap.dedent(
        """
        import resource
        from quilting.service.memory_limit import MiB, _status_bytes, limit_memory

        _, hard = resource.getrlimit(resource.RLIMIT_DATA)
        cap = limit_memory(32 * MiB)
        assert resource.getrlimit(resource.RLIMIT_DATA) == (cap, hard), (cap, hard)
        assert 0 < cap - _status_bytes("VmData") <= 32 * MiB, cap
        try:
            bytearray(256 * MiB)
        except MemoryError:
            pass
        else:
            raise AssertionError("256 MiB allocated past a 32 MiB budget")
        bytearray(MiB)  # the process goes on

        low = _status_bytes("VmData") + 8 * MiB
        resource.setrlimit(resource.RLIMIT_DATA, (low, low))
        assert limit_memory(64 * MiB) == low
        assert resource.getrlimit(resource.RLIMIT_DATA) == (low, low)
        print("ok")
        """
    )
    before = resource.getrlimit(resource.RLIMIT_DATA)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "ok\n"
    assert resource.getrlimit(resource.RLIMIT_DATA) == before  # this process as it was


@pytest.mark.parametrize(
    ("count", "words"),
    [
        (0, "0 MiB"),
        (MiB // 2, "0.5 MiB"),
        (MiB, "1 MiB"),
        (150 * MiB, "150 MiB"),
        (999 * MiB, "999 MiB"),
        (1000 * MiB, "1000 MiB"),  # no "1e+03 MiB" between 1000 and 1023 MiB
        (GiB - 1, "1024 MiB"),
        (99 * MiB + MiB // 2, "99.5 MiB"),
        (1, "0.00 MiB"),
        (GiB, "1 GiB"),
        (3 * GiB // 2, "1.5 GiB"),
        (2 * GiB, "2 GiB"),
        (64 * GiB, "64 GiB"),
    ],
)
def test_describe_bytes_in_words(count: int, words: str) -> None:
    assert describe_bytes(count) == words
