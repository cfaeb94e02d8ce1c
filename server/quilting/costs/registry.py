"""The backend registry: names, construction, and why a backend is or is not available.

The interface itself (:class:`CostBackend`, :class:`CostRequest`, :class:`FieldBatch`) is
declared by the core in :mod:`quilting.core.fields`, because the core drives it and may not
import upwards; it is re-exported here for backend authors.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass

from quilting.core.errors import BackendError, InvalidParameterError
from quilting.core.fields import CostBackend, CostRequest, FieldBatch
from quilting.costs.variables import BACKEND_VARIABLE, GL_DEVICE_VARIABLE

__all__ = [
    "BACKEND_NAMES",
    "BACKEND_VARIABLE",
    "GL_DEVICE_VARIABLE",
    "BackendStatus",
    "CostBackend",
    "CostRequest",
    "FieldBatch",
    "auto_choice",
    "available_backends",
    "backend_renderer",
    "get_backend",
    "gl_status",
    "resolve_name",
]

BACKEND_NAMES = ("auto", "fft", "gl", "reference")


@dataclass(frozen=True)
class BackendStatus:
    """Whether a backend can run here, and why (for ``quilting info``)."""

    name: str
    available: bool
    reason: str
    renderer: str | None = None
    #: True when ``auto`` picks this backend here.
    preferred: bool = False


def _fft() -> CostBackend:
    from quilting.costs.fft import FFTBackend

    return FFTBackend()


def _reference() -> CostBackend:
    from quilting.costs.reference import ReferenceBackend

    return ReferenceBackend()


def _gl() -> CostBackend:
    try:
        from quilting.costs.gl import GLBackend
    except ImportError as exc:
        raise BackendError(
            f"backend 'gl' needs moderngl (pip install 'quilting[gl]'): {exc}"
        ) from exc
    return GLBackend()


_FACTORIES: dict[str, Callable[[], CostBackend]] = {
    "fft": _fft,
    "gl": _gl,
    "reference": _reference,
}


def gl_status(create_context: bool = True) -> BackendStatus:
    """Whether the ``gl`` backend can run here, its renderer, and whether ``auto`` uses it.

    With ``create_context=False`` no context is made on a machine without a GPU device file
    (the cheap answer ``auto`` needs); otherwise the context is made (or reused) to name the
    renderer, a software one included.
    """
    try:
        from quilting.costs import gl
    except ImportError as exc:
        return BackendStatus("gl", False, f"moderngl is not installed (quilting[gl]): {exc}")
    nodes = gl.gpu_device_nodes()
    if not nodes and not create_context:
        return BackendStatus(
            "gl", False, "no GPU device here (no /dev/nvidia*, no /dev/dri/renderD*)"
        )
    try:
        info = gl.probe()
    except BackendError as exc:
        return BackendStatus("gl", False, exc.message)
    forced = _forced()
    if info.software:
        return BackendStatus(
            "gl",
            True,
            f"runs on {info.renderer}, a software rasterizer (many times slower than fft "
            f"on the same CPU): used when asked for by name, auto uses {forced or 'fft'}",
            info.renderer,
            preferred=forced == "gl",
        )
    # The operator's QUILTING_BACKEND decides for auto even on a GPU.
    uses = "gl" if forced is None else f"{forced} ({BACKEND_VARIABLE})"
    return BackendStatus(
        "gl",
        True,
        f"hardware GPU: {info.renderer}; auto uses {uses}",
        info.renderer,
        preferred=forced in (None, "gl"),
    )


def available_backends() -> list[BackendStatus]:
    """Every backend name with whether it can start on this machine and why."""
    picked = auto_choice()[0]
    return [
        BackendStatus(
            "fft",
            True,
            "CPU FFT correlation (scipy.fft); always available",
            "cpu",
            picked == "fft",
        ),
        gl_status(create_context=True),
        BackendStatus(
            "reference",
            True,
            "direct sums in numpy; slow, the test oracle",
            "cpu",
            picked == "reference",
        ),
    ]


def _check_name(name: str, parameter: str = "backend") -> None:
    if name not in BACKEND_NAMES:
        raise InvalidParameterError(
            parameter, name, "one of " + ", ".join(map(repr, BACKEND_NAMES))
        )


def _forced() -> str | None:
    """The backend ``QUILTING_BACKEND`` names for ``auto`` (validated), or None if unset."""
    forced = os.environ.get(BACKEND_VARIABLE, "").strip()
    if not forced or forced == "auto":
        return None
    _check_name(forced, BACKEND_VARIABLE)
    return forced


def auto_choice() -> tuple[str, str]:
    """``(backend, why)``: what ``auto`` stands for on this machine.

    ``QUILTING_BACKEND`` decides when set; otherwise a hardware GPU means ``gl`` and anything
    else (no GPU, a software rasterizer, no moderngl) ``fft``.
    """
    forced = _forced()
    if forced is not None:
        return forced, f"{BACKEND_VARIABLE}={forced}"
    status = gl_status(create_context=False)
    if status.preferred:  # with no QUILTING_BACKEND: a hardware GPU
        return "gl", f"hardware GPU: {status.renderer}"
    if status.renderer is not None:
        return "fft", f"the GL renderer is a software rasterizer ({status.renderer})"
    return "fft", status.reason


def backend_renderer(name: str) -> tuple[str, str | None, str]:
    """``(backend, renderer, why)`` for jobs asking for ``name``; renderer None if it cannot run.

    The renderer is ``"cpu"`` for the CPU backends and the GL renderer string for ``gl``.
    """
    _check_name(name)
    if name == "auto":
        concrete, why = auto_choice()
    else:
        concrete, why = name, "asked for by name"
    if concrete != "gl":
        return concrete, "cpu", why
    status = gl_status(create_context=True)
    return (
        "gl",
        status.renderer if status.available else None,
        (why if status.available else status.reason),
    )


def resolve_name(name: str) -> str:
    """The concrete backend ``name`` stands for (``auto``: see :func:`auto_choice`)."""
    _check_name(name)
    return auto_choice()[0] if name == "auto" else name


def get_backend(name: str) -> CostBackend:
    """Construct the backend called ``name``.

    A backend asked for by name that cannot start raises :class:`BackendError`; there is no
    silent fallback. ``auto`` resolved to ``gl`` falls back to ``fft`` if the GPU fails, at
    start or during the job (see :class:`quilting.costs.fallback.FallbackBackend`).
    """
    _check_name(name)
    if name == "auto":
        # The operator's QUILTING_BACKEND counts as asking by name: no fallback either.
        name = auto_choice()[0]
        if name == "gl" and _forced() is None:
            from quilting.costs.fallback import FallbackBackend

            return FallbackBackend(_gl, _fft)
    try:
        return _FACTORIES[name]()
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise BackendError(f"backend {name!r} cannot start: {exc}") from exc
