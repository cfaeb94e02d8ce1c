"""The cost-field backends as the upper layers see them: their names, whether each can run
here and why, what ``auto`` stands for, and how to start one.

The service and the command line take everything about backends from here (DESIGN: they use
the public API, never :mod:`quilting.costs` directly); the registry behind it is
:mod:`quilting.costs.registry`.

>>> import quilting.backends
>>> quilting.backends.BACKEND_NAMES
('auto', 'fft', 'gl', 'reference')
"""

from quilting.core.fields import CostBackend
from quilting.costs.registry import (
    BACKEND_NAMES,
    BACKEND_VARIABLE,
    GL_DEVICE_VARIABLE,
    BackendStatus,
    auto_choice,
    available_backends,
    backend_renderer,
    get_backend,
    gl_status,
    resolve_name,
)

__all__ = [
    "BACKEND_NAMES",
    "BACKEND_VARIABLE",
    "GL_DEVICE_VARIABLE",
    "BackendStatus",
    "CostBackend",
    "auto_choice",
    "available_backends",
    "backend_renderer",
    "get_backend",
    "gl_status",
    "resolve_name",
]
