"""The one exception tree of the package.

Every error the engine raises on purpose is a :class:`QuiltingError` with a stable ``code``
(the service maps it to ``application/problem+json``). Messages name the parameter, the value
and what is allowed, so a user can fix the call without reading the source.
"""

from __future__ import annotations

from typing import Any


class QuiltingError(Exception):
    """Base of every error raised on purpose by quilting."""

    code: str = "quilting_error"

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class InvalidParameterError(QuiltingError, ValueError):
    """A parameter is outside its allowed range or of the wrong type.

    Parameters
    ----------
    parameter : str
        Name of the parameter, as the user spells it (``"block"``, ``"size"``...).
    value : Any
        The value that was given.
    allowed : str
        What would have been accepted, in words (``"3..256"``, ``"one of 'cut', 'overlap'"``).
    reason : str, optional
        Why the value is refused, when ``allowed`` alone does not say it.
    """

    code = "invalid_parameter"

    def __init__(self, parameter: str, value: Any, allowed: str, reason: str = "") -> None:
        detail = f"{parameter}={value!r} is not allowed"
        if reason:
            detail += f": {reason}"
        detail += f" (allowed: {allowed})"
        super().__init__(detail)
        self.parameter = parameter
        self.value = value
        self.allowed = allowed


class InvalidImageError(QuiltingError, ValueError):
    """An image array has the wrong shape, dtype or contains NaN/inf.

    ``parameter``, when given, names the argument the image came as (``"silhouette"``...).
    """

    code = "invalid_image"

    def __init__(self, message: str, parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter


class ImageDecodeError(QuiltingError):
    """Bytes or a file could not be read as a PNG or JPEG image."""

    code = "unreadable_image"


class ImageTooLargeError(QuiltingError):
    """An image declares more pixels than the configured limit (checked before decoding)."""

    code = "image_too_large"


class LayoutError(QuiltingError, ValueError):
    """A layout file is malformed or does not fit the map it is applied to."""

    code = "invalid_layout"


class BackendError(QuiltingError):
    """A cost backend is unknown, cannot start, or failed while computing."""

    code = "backend_unavailable"


class CancelledError(QuiltingError):
    """The job was cancelled between two wavefront levels."""

    code = "cancelled"
