"""The backend registry: names, construction, and why a backend is or is not available.

The interface itself (:class:`CostBackend`, :class:`CostRequest`, :class:`FieldBatch`) is
declared by the core in :mod:`quilting.core.fields`, because the core drives it and may not
import upwards; it is re-exported here for backend authors.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from quilting.core.errors import BackendError, InvalidParameterError
from quilting.core.fields import CostBackend, CostRequest, FieldBatch

__all__ = [
    "BACKEND_NAMES",
    "BackendStatus",
    "CostBackend",
    "CostRequest",
    "FieldBatch",
    "available_backends",
    "get_backend",
]

BACKEND_NAMES = ("auto", "fft", "reference")


@dataclass(frozen=True)
class BackendStatus:
    """Whether a backend can run here, and why (for ``quilting info``)."""

    name: str
    available: bool
    reason: str


def _fft() -> CostBackend:
    from quilting.costs.fft import FFTBackend

    return FFTBackend()


def _reference() -> CostBackend:
    from quilting.costs.reference import ReferenceBackend

    return ReferenceBackend()


_FACTORIES: dict[str, Callable[[], CostBackend]] = {"fft": _fft, "reference": _reference}


def available_backends() -> list[BackendStatus]:
    """Every backend name with whether it can start on this machine and why."""
    return [
        BackendStatus("fft", True, "CPU FFT correlation (scipy.fft); always available"),
        BackendStatus("reference", True, "direct sums in numpy; slow, the test oracle"),
        BackendStatus(
            "gl",
            False,
            "GLSL compute shaders are not part of this build yet",
        ),
    ]


def resolve_name(name: str) -> str:
    """The concrete backend ``name`` stands for (``auto`` picks the fastest available)."""
    if name not in BACKEND_NAMES:
        raise InvalidParameterError(
            "backend", name, "one of " + ", ".join(map(repr, BACKEND_NAMES))
        )
    return "fft" if name == "auto" else name


def get_backend(name: str) -> CostBackend:
    """Construct the backend called ``name``.

    A backend asked for by name that cannot start raises :class:`BackendError`; there is no
    silent fallback.
    """
    concrete = resolve_name(name)
    try:
        return _FACTORIES[concrete]()
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise BackendError(f"backend {concrete!r} cannot start: {exc}") from exc
