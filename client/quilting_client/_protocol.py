"""The HTTP contract of the quilting service, without any I/O.

Builds request descriptions (:class:`RequestSpec`) and interprets responses (status JSON,
problem bodies, ``Retry-After``, server-sent events). The sync and async clients both use this
module, so what goes over the wire is defined once.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from email.utils import parsedate_to_datetime
from pathlib import Path
from time import time
from typing import Any
from urllib.parse import quote

import httpx

from quilting_client._version import __version__
from quilting_client.errors import (
    ConnectionFailedError,
    QuiltingClientError,
    ValidationError,
    error_from_problem,
)
from quilting_client.models import JobStatus

#: What an image (a texture, a target, a companion map, an image to tile, a matte's silhouette,
#: layer or normal map) may be given as: a path, or the file's bytes.
ImageSource = str | os.PathLike[str] | bytes

_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_SIGNATURE = b"\xff\xd8\xff"


@dataclass(frozen=True)
class RequestSpec:
    """One HTTP request to make, relative to the client's base URL.

    Attributes
    ----------
    method, path : str
        The HTTP method and the path (already percent-encoded).
    params, headers : Mapping[str, str]
        Query parameters and extra headers.
    files : tuple
        Multipart file parts as httpx takes them: ``(field, (filename, content, type))``.
    data : Mapping[str, str]
        Multipart form fields.
    hold : float
        Seconds the service may hold the response on purpose (``?wait=``); added to the read
        timeout so that a long wait is not mistaken for a dead connection.
    timeout : float or None
        Seconds allowed to connect, send and wait for each read of this request, in place of
        the client's timeout; None keeps the client's.
    """

    method: str
    path: str
    params: Mapping[str, str] = field(default_factory=dict)
    headers: Mapping[str, str] = field(default_factory=dict)
    files: tuple[tuple[str, tuple[str, bytes, str]], ...] = ()
    data: Mapping[str, str] = field(default_factory=dict)
    hold: float = 0.0
    timeout: float | None = None


@dataclass(frozen=True)
class Finished:
    """A ``POST /synthesize``, ``/transfer`` or ``/matte`` answered with the result PNG itself
    (HTTP 200).

    Attributes
    ----------
    image : bytes
        The result PNG.
    job_id : str or None
        From ``X-Job-Id`` (or ``Location``).
    """

    image: bytes
    job_id: str | None


@dataclass(frozen=True)
class ServerEvent:
    """One server-sent event: its name and its JSON data."""

    name: str
    data: dict[str, Any]


def default_headers(api_key: str | None) -> dict[str, str]:
    """Headers sent with every request: the user agent and, if given, the API key."""
    headers = {"User-Agent": f"quilting-client/{__version__}"}
    if api_key:
        headers["Authorization"] = f"Bearer {api_key}"
    return headers


def request_kwargs(spec: RequestSpec, timeout: httpx.Timeout) -> dict[str, Any]:
    """The keyword arguments of ``httpx.Client.build_request`` (and the async one) for a spec."""
    kwargs: dict[str, Any] = {
        "method": spec.method,
        "url": spec.path,
        "params": dict(spec.params) or None,
        "headers": dict(spec.headers) or None,
        "timeout": timeout,
    }
    if spec.files:
        kwargs["files"] = list(spec.files)
        kwargs["data"] = dict(spec.data)
    return kwargs


def request_timeout(base: float, spec: RequestSpec) -> httpx.Timeout:
    """The timeout of a plain request: the client's (or the request's own), plus the time the
    service may hold it."""
    if spec.timeout is not None:
        base = spec.timeout
    return httpx.Timeout(base, read=base + spec.hold)


def stream_timeout(base: float, limit: float | None) -> httpx.Timeout:
    """The timeout of an event stream followed for at most ``limit`` seconds.

    Between two events the stream may be silent for a while; the read timeout bounds that
    silence so that a dead connection or an expired deadline is noticed. A stream followed
    without a limit (``events()``) has no read timeout: it waits for events forever.
    """
    if limit is None:
        return httpx.Timeout(base, read=None)
    # A floor: a read timeout of (almost) zero would fail before the headers of a healthy
    # service arrive.
    return httpx.Timeout(base, read=min(base, max(limit, 0.1)))


def job_path(job_id: str, *rest: str) -> str:
    """The path of a job resource; ids and names are percent-encoded, ``/`` included."""
    return "/".join(["/jobs", *(quote(part, safe="") for part in (job_id, *rest))])


def read_source(source: ImageSource) -> tuple[bytes, str | None]:
    """The bytes of an image given as a path or as bytes, and the file's name if it has one."""
    if isinstance(source, bytes | bytearray | memoryview):
        return bytes(source), None
    path = Path(os.fspath(source))
    return path.read_bytes(), path.name


def _media_type(content: bytes) -> str:
    # The service sniffs the bytes itself; a matching type only helps proxies and logs.
    if content.startswith(_PNG_SIGNATURE):
        return "image/png"
    if content.startswith(_JPEG_SIGNATURE):
        return "image/jpeg"
    return "application/octet-stream"


def _part(field: str, source: ImageSource) -> tuple[str, tuple[str, bytes, str]]:
    """One multipart file part; an image given as bytes is named after its field."""
    content, filename = read_source(source)
    return (field, (filename or field, content, _media_type(content)))


def check_companion_name(name: object) -> str:
    """``name`` if the service would take it as a companion's name; else raise.

    Raises
    ------
    ValidationError
        A name that is not 1 to 64 of ``A-Z a-z 0-9 _ -`` (checked here to fail before
        uploading).
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValidationError(
            f"companion name {name!r} is not 1 to 64 of A-Z a-z 0-9 _ -",
            code="invalid_companion_name",
            field="companion",
        )
    return name


def _image_parts(
    texture: ImageSource,
    target: ImageSource | None,
    companions: Mapping[str, ImageSource] | None,
) -> tuple[tuple[str, tuple[str, bytes, str]], ...]:
    """The multipart file parts of a submission: texture, target (if any), companions."""
    files = [_part("texture", texture)]
    if target is not None:
        files.append(_part("target", target))
    for name, source in (companions or {}).items():
        check_companion_name(name)
        data, _ = read_source(source)
        # The service names a companion after its part's filename stem.
        files.append(("companion", (f"{name}.png", data, _media_type(data))))
    return tuple(files)


def _sources(value: Iterable[ImageSource], what: str) -> list[ImageSource]:
    """The images of a sequence, refusing a lone image (a path is a sequence of characters)."""
    if isinstance(value, str | bytes | bytearray | memoryview | os.PathLike):
        raise TypeError(f"{what} is a sequence of images: put a single image in a list")
    return list(value)


def output_names(names: Iterable[str]) -> tuple[str, ...]:
    """The names of companions to download, checked, in order and without repeats.

    Raises
    ------
    TypeError
        ``names`` is one string rather than a collection of names.
    ValidationError
        A name the service could not have given a companion.
    """
    if isinstance(names, str):
        raise TypeError(f"companions is a collection of names: put {names!r} in a tuple")
    return tuple(dict.fromkeys(check_companion_name(name) for name in names))


def _post(
    path: str,
    files: tuple[tuple[str, tuple[str, bytes, str]], ...],
    document: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
    companion_kinds: Mapping[str, str] | None = None,
) -> RequestSpec:
    headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
    data = {"options": json.dumps(dict(document))}
    if companion_kinds:
        # Left out when empty: every companion is then 'blend', as for an older service.
        data["companion_kinds"] = json.dumps(dict(companion_kinds))
    return RequestSpec(
        "POST",
        path,
        params={"wait": f"{wait:g}"},
        headers=headers,
        files=files,
        data=data,
        hold=wait,
    )


#: How a companion may be rendered (the service's ``companion_kinds`` values).
COMPANION_KINDS = ("blend", "hard", "normal")


def check_companion_kinds(
    kinds: Mapping[str, str] | None, companions: Mapping[str, ImageSource] | None
) -> dict[str, str]:
    """``kinds`` if every name is one of ``companions`` and every kind one the service takes.

    Raises
    ------
    ValidationError
        Checked here to fail before uploading: code ``invalid_companion`` for an unknown
        name, ``invalid_parameter`` for an unknown kind.
    """
    for name, kind in (kinds or {}).items():
        if name not in (companions or {}):
            raise ValidationError(
                f"companion_kinds names {name!r}, which is not one of the companions sent",
                code="invalid_companion",
                field="companion_kinds",
            )
        if kind not in COMPANION_KINDS:
            raise ValidationError(
                f"companion kind {kind!r} of {name!r} is not one of {', '.join(COMPANION_KINDS)}",
                code="invalid_parameter",
                field="companion_kinds",
            )
    return dict(kinds or {})


def _given(options: Mapping[str, object]) -> dict[str, object]:
    # None values are left out so that the service's defaults apply.
    return {k: v for k, v in options.items() if v is not None}


def submit_request(
    texture: ImageSource,
    *,
    width: int,
    height: int,
    companions: Mapping[str, ImageSource] | None,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
    companion_kinds: Mapping[str, str] | None = None,
) -> RequestSpec:
    """The ``POST /synthesize`` request.

    Parameters
    ----------
    texture : str, PathLike or bytes
        The sample texture (PNG or JPEG).
    width, height : int
        Output size in pixels.
    companions : Mapping or None
        Companion maps by name; each becomes a ``companion`` part named ``<name>.png``.
    companion_kinds : Mapping or None
        How companions are rendered ('blend', 'hard' or 'normal') by name; the
        ``companion_kinds`` field.
    options : Mapping
        Further synthesis options; None values are left out so the service's defaults apply.
    wait : float
        Seconds the service may hold the response for the result (``?wait=``).
    idempotency_key : str or None
        Sent as ``Idempotency-Key``.

    Returns
    -------
    RequestSpec

    Raises
    ------
    ValidationError
        A companion name the service would reject (checked here to fail before uploading).
    OSError
        A path that cannot be read.
    """
    kinds = check_companion_kinds(companion_kinds, companions)
    files = _image_parts(texture, None, companions)
    document = {"width": width, "height": height, **_given(options)}
    return _post("/synthesize", files, document, wait, idempotency_key, kinds)


def transfer_request(
    texture: ImageSource,
    target: ImageSource,
    *,
    companions: Mapping[str, ImageSource] | None,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
    companion_kinds: Mapping[str, str] | None = None,
) -> RequestSpec:
    """The ``POST /transfer`` request.

    Parameters
    ----------
    texture : str, PathLike or bytes
        The texture to render with (PNG or JPEG).
    target : str, PathLike or bytes
        The image to render (PNG or JPEG); the output has its size.
    companions, options, wait, idempotency_key, companion_kinds
        As for :func:`submit_request` (the options are transfer options, without a size).

    Returns
    -------
    RequestSpec

    Raises
    ------
    ValidationError
        A companion name the service would reject.
    OSError
        A path that cannot be read.
    """
    kinds = check_companion_kinds(companion_kinds, companions)
    files = _image_parts(texture, target, companions)
    return _post("/transfer", files, _given(options), wait, idempotency_key, kinds)


def matte_request(
    target: ImageSource,
    silhouette: ImageSource,
    layers: Sequence[ImageSource],
    *,
    normals: ImageSource | None,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
) -> RequestSpec:
    """The ``POST /matte`` request: lay textures on the surface of an object (texture matting).

    Parameters
    ----------
    target : str, PathLike or bytes
        The image with the object (PNG or JPEG); the output has its size.
    silhouette : str, PathLike or bytes
        The target's size: white (or opaque) where the surface is, black elsewhere.
    layers : sequence of str, PathLike or bytes
        The textures to lay on the surface, bottom first; each becomes a ``layer`` part, in
        this order.
    normals : str, PathLike, bytes or None
        A normal map of the target's size to use instead of the one read from the shading;
        None sends no ``normals`` part.
    options : Mapping
        Matte options (``MatteOptions``); None values are left out so the service's defaults
        apply.
    wait, idempotency_key
        As for :func:`submit_request`.

    Returns
    -------
    RequestSpec
        The file parts in the order target, silhouette, the layers, normals.

    Raises
    ------
    ValidationError
        No layer (code ``missing_field``, checked here to fail before uploading).
    TypeError
        ``layers`` is a single image rather than a sequence of them.
    OSError
        A path that cannot be read.
    """
    sources = _sources(layers, "layers")
    if not sources:
        raise ValidationError(
            "layers: at least one texture is needed", code="missing_field", field="layer"
        )
    files = [_part("target", target), _part("silhouette", silhouette)]
    files += [_part("layer", layer) for layer in sources]
    if normals is not None:
        files.append(_part("normals", normals))
    return _post("/matte", tuple(files), _given(options), wait, idempotency_key)


def tile_request(
    image: ImageSource,
    *,
    axes: str,
    band: int | None,
    blend: str | None = None,
    timeout: float | None = None,
) -> RequestSpec:
    """The ``POST /tile`` request: make an image repeat seamlessly, answered at once.

    Parameters
    ----------
    image : str, PathLike or bytes
        The image to make tileable (PNG or JPEG); the output has its size and bit depth.
    axes : str
        Which wraps must be seamless: ``"both"``, ``"x"`` or ``"y"`` (checked by the service).
    band : int or None
        Width in pixels of the border bands the cuts may wander in; None is left out, so the
        service's default (a quarter of each side) applies.
    blend : str or None
        How the cuts are joined: ``"none"`` (as they are) or ``"poisson"`` (blended in the
        gradient domain; checked by the service); None is left out: the service's default.
    timeout : float or None
        Seconds allowed to connect, send and wait for each read, in place of the client's
        timeout; None keeps the client's.

    Returns
    -------
    RequestSpec
        No ``?wait=`` and no ``Idempotency-Key``: the service creates no job.

    Raises
    ------
    OSError
        A path that cannot be read.
    """
    files = (_part("image", image),)
    document = _given({"axes": axes, "band": band, "blend": blend})
    return RequestSpec(
        "POST",
        "/tile",
        headers={"Accept": "image/png"},
        files=files,
        data={"options": json.dumps(document)},
        timeout=timeout,
    )


def job_request(job_id: str) -> RequestSpec:
    """``GET /jobs/{id}``: the job's status."""
    return RequestSpec("GET", job_path(job_id))


def result_request(job_id: str, name: str | None = None) -> RequestSpec:
    """``GET /jobs/{id}/result`` or, with a name, ``GET /jobs/{id}/result/{name}``."""
    rest = ("result",) if name is None else ("result", name)
    return RequestSpec("GET", job_path(job_id, *rest), headers={"Accept": "image/png"})


def layout_request(job_id: str) -> RequestSpec:
    """``GET /jobs/{id}/layout``: the layout document."""
    return RequestSpec("GET", job_path(job_id, "layout"))


def cancel_request(job_id: str) -> RequestSpec:
    """``DELETE /jobs/{id}``: cancel the job."""
    return RequestSpec("DELETE", job_path(job_id))


def events_request(job_id: str) -> RequestSpec:
    """``GET /jobs/{id}/events``: the job's server-sent events."""
    return RequestSpec(
        "GET",
        job_path(job_id, "events"),
        headers={"Accept": "text/event-stream", "Cache-Control": "no-cache"},
    )


def health_request() -> RequestSpec:
    """``GET /healthz``."""
    return RequestSpec("GET", "/healthz")


def ready_request() -> RequestSpec:
    """``GET /readyz``."""
    return RequestSpec("GET", "/readyz")


def retry_after(response: httpx.Response) -> float | None:
    """The ``Retry-After`` header in seconds (delta-seconds or an HTTP date), or None."""
    value = response.headers.get("Retry-After")
    if value is None:
        return None
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        return max(0.0, parsedate_to_datetime(value).timestamp() - time())
    except (TypeError, ValueError):
        return None


def problem_of(response: httpx.Response) -> dict[str, Any]:
    """The problem document of an error response; a synthetic one if the body is not JSON."""
    try:
        body = response.json()
    except ValueError:
        body = None
    if isinstance(body, dict) and body:
        return body
    # A proxy or a crashed worker may answer in plain text or HTML: keep the status and a
    # short, single-line excerpt so that the error still says something useful.
    reason = response.reason_phrase or "error"
    text = " ".join(response.text.split())[:200]
    detail = f"{reason}: {text}" if text and not text.startswith("<") else reason
    return {"title": reason, "status": response.status_code, "detail": detail}


def raise_for_problem(response: httpx.Response) -> None:
    """Raise the typed error of an error response (status >= 400); return otherwise.

    The body must have been read.
    """
    if response.status_code < 400:
        return
    raise error_from_problem(
        problem_of(response), status=response.status_code, retry_after=retry_after(response)
    )


def connection_error(exc: httpx.TransportError, request: httpx.Request) -> ConnectionFailedError:
    """The client error for an httpx transport failure (refused, reset, timed out...)."""
    kind = type(exc).__name__
    reason = str(exc) or kind
    return ConnectionFailedError(
        f"{request.method} {request.url}: {reason}", code="connection_failed"
    )


def _invalid_response(response: httpx.Response, why: str) -> QuiltingClientError:
    return QuiltingClientError(
        f"unexpected response to {response.request.method} {response.request.url.path}: {why}",
        status=response.status_code,
        code="invalid_response",
    )


def parse_json_object(response: httpx.Response) -> dict[str, Any]:
    """The JSON object of a successful response."""
    try:
        body = response.json()
    except ValueError:
        raise _invalid_response(response, "the body is not JSON") from None
    if not isinstance(body, dict):
        raise _invalid_response(response, "the body is not a JSON object")
    return body


def parse_job(response: httpx.Response) -> JobStatus:
    """The job status in a successful response."""
    try:
        return JobStatus.from_json(parse_json_object(response))
    except ValueError as exc:
        raise _invalid_response(response, str(exc)) from None


def job_id_of(response: httpx.Response) -> str | None:
    """The job id a response names in ``X-Job-Id``, or else in ``Location: /jobs/<id>``."""
    job_id: str | None = response.headers.get("X-Job-Id")
    if job_id:
        return job_id
    location = response.headers.get("Location", "")
    if "/jobs/" in location:
        return location.rsplit("/jobs/", 1)[1].split("/", 1)[0] or None
    return None


def parse_png(response: httpx.Response) -> bytes:
    """The PNG of a successful response that must be one (``POST /tile``)."""
    if not response.content.startswith(_PNG_SIGNATURE):
        raise _invalid_response(response, "the body is not a PNG")
    return response.content


def parse_submit(response: httpx.Response) -> Finished | JobStatus:
    """Interpret the answer to a submission: the result itself, or the job's status."""
    media_type = response.headers.get("Content-Type", "").split(";")[0].strip().lower()
    if response.status_code == 202 or media_type.endswith("json"):
        return parse_job(response)
    return Finished(image=response.content, job_id=job_id_of(response))


def _event_data(text: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except ValueError:
        return {"data": text}
    return value if isinstance(value, dict) else {"data": value}


class SSEDecoder:
    """Incremental decoder of a ``text/event-stream``, fed one line at a time.

    Follows the WHATWG rules that matter here: ``event:`` names the event, ``data:`` lines
    are joined with newlines, a blank line dispatches, ``:`` starts a comment. ``id:`` and
    ``retry:`` are ignored: after a broken stream the client asks for the job's status, which
    is complete, instead of resuming from an event id.
    """

    def __init__(self) -> None:
        self._name = ""
        self._data: list[str] = []

    def feed(self, line: str) -> ServerEvent | None:
        """Take one line (without its terminator); return the event it completes, if any."""
        if not line:
            return self._dispatch()
        if line.startswith(":"):
            return None
        name, colon, value = line.partition(":")
        if colon and value.startswith(" "):
            value = value[1:]
        if name == "event":
            self._name = value
        elif name == "data":
            self._data.append(value)
        return None

    def flush(self) -> ServerEvent | None:
        """At the end of the stream: the last event if the final blank line was missing.

        The standard drops such an event; keeping it is kinder to a terminal event written
        just before the connection closed.
        """
        return self._dispatch()

    def _dispatch(self) -> ServerEvent | None:
        name, data = self._name or "message", self._data
        self._name, self._data = "", []
        if not data:
            return None
        return ServerEvent(name, _event_data("\n".join(data)))
