"""Python client of the quilting texture-synthesis (transfer, matting, filling, tiling, Wang
tiles) HTTP service.

>>> from quilting_client import Client
>>> with Client("http://127.0.0.1:8000") as client:  # doctest: +SKIP
...     png = client.synthesize("gravel.png", width=512, height=512, block=32)
...     art = client.transfer("gravel.png", "portrait.png", block=16, iterations=2)
...     vase = client.matte("vase.png", "vase_mask.png", ["brick.png"], companions=["normals"])
...     clean = client.fill("photo.png", "stain_mask.png", block=24)
...     wider = client.extend("photo.png", left=128, right=128)
...     seamless = client.tile("photo.png", axes="both")
...     mixed = client.synthesize(["gravel.png", "gravel2.png"], width=512, height=512)
...     tiles = client.wang_tiles("gravel.png", colors=2, tile=128)  # tiles.manifest

Synthesis, transfer, matting, filling, extending and Wang tile sets run as jobs that the client
follows; ``tile`` is answered at once.

:class:`Client` blocks, :class:`AsyncClient` is its asyncio twin; both raise the typed errors
of :mod:`quilting_client.errors`. Only ``httpx`` is needed: neither numpy nor the engine.
"""

from quilting_client._async import AsyncClient
from quilting_client._sync import Client
from quilting_client._version import __version__
from quilting_client.errors import (
    AuthenticationError,
    ConflictError,
    ConnectionFailedError,
    GoneError,
    JobCancelledError,
    JobError,
    JobFailedError,
    NotFoundError,
    PayloadTooLargeError,
    QuiltingClientError,
    ServerError,
    ServiceUnavailableError,
    UnsupportedMediaTypeError,
    ValidationError,
    WaitTimeoutError,
)
from quilting_client.models import JobStatus, SynthesisResult, WangTilesResult

__all__ = [
    "AsyncClient",
    "AuthenticationError",
    "Client",
    "ConflictError",
    "ConnectionFailedError",
    "GoneError",
    "JobCancelledError",
    "JobError",
    "JobFailedError",
    "JobStatus",
    "NotFoundError",
    "PayloadTooLargeError",
    "QuiltingClientError",
    "ServerError",
    "ServiceUnavailableError",
    "SynthesisResult",
    "UnsupportedMediaTypeError",
    "ValidationError",
    "WaitTimeoutError",
    "WangTilesResult",
    "__version__",
]
