"""The requests of the quilting service's HTTP contract, built without any I/O.

Every call of the clients starts here: a :class:`RequestSpec` says what to send (method, path,
query, headers, multipart parts, timeouts), and :func:`request_kwargs` turns it into the
arguments of ``httpx.Client.build_request`` (and the async one). The sync and async clients
both use this module, so what goes over the wire is defined once. The files uploaded are
prepared by :mod:`quilting_client._uploads`; the answers are read by
:mod:`quilting_client._responses` and :mod:`quilting_client._events`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NotRequired, TypedDict, Unpack, cast
from urllib.parse import quote

import httpx

from quilting_client._uploads import (
    ImageSource,
    check_companion_kinds,
    check_companion_name,
    images_of,
    media_type,
    one_or_many,
    part,
    read_source,
)
from quilting_client._version import __version__
from quilting_client.errors import ValidationError


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


def client_settings(base_url: str, api_key: str | None, timeout: float) -> dict[str, Any]:
    """The keyword arguments of ``httpx.Client`` (and the async one) but the transport.

    Every request carries the user agent and, if given, the API key.
    """
    headers = {"User-Agent": f"quilting-client/{__version__}"}
    if api_key:
        headers["Authorization"] = f"Bearer {api_key}"
    return {"base_url": base_url, "headers": headers, "timeout": timeout}


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


def _given(options: Mapping[str, object]) -> dict[str, object]:
    # None values are left out so that the service's defaults apply.
    return {k: v for k, v in options.items() if v is not None}


class Submission(TypedDict):
    """The arguments that :func:`submit_request` and :func:`transfer_request` share.

    Attributes
    ----------
    companions : Mapping or None
        Companion maps by name; each becomes a ``companion`` part named ``<name>.png``. With
        several textures (a synthesis), each value is a sequence of one map per texture, in
        their order, sent as that many parts of the same name.
    companion_kinds : Mapping or None
        How companions are rendered ('blend', 'hard', 'normal' or 'normal_dx') by name; the
        ``companion_kinds`` field. Optional: None.
    options : Mapping
        Further options of the operation; None values are left out so the service's defaults
        apply.
    wait : float
        Seconds the service may hold the response for the result (``?wait=``).
    idempotency_key : str or None
        Sent as ``Idempotency-Key``.
    """

    companions: Mapping[str, ImageSource | Sequence[ImageSource]] | None
    companion_kinds: NotRequired[Mapping[str, str] | None]
    options: Mapping[str, object]
    wait: float
    idempotency_key: str | None


def _companion_parts(
    companions: Mapping[str, ImageSource | Sequence[ImageSource]] | None, textures: int = 1
) -> list[tuple[str, tuple[str, bytes, str]]]:
    """A ``companion`` part per companion map, named ``<name>.png`` (the service names a
    companion after its part's filename stem); each name checked first. With several
    ``textures``, each companion is a sequence of one map per texture, sent in order as that
    many parts of the same name (one map alone stands for the one texture's)."""
    parts = []
    for name, sources in (companions or {}).items():
        check_companion_name(name)
        maps = _per_texture(sources, textures, "companion", f"companion {name!r}", "map")
        for source in maps:
            data, _ = read_source(source)
            parts.append(("companion", (f"{name}.png", data, media_type(data))))
    return parts


def _quilt_request(
    path: str,
    texture: ImageSource | Sequence[ImageSource],
    target: ImageSource | None,
    size: Mapping[str, int],
    submission: Submission,
    source_mask: ImageSource | Sequence[ImageSource] | None = None,
    marks: Marks = None,
    strokes: Marks = None,
) -> RequestSpec:
    """A synthesis or transfer: the texture (or several examples), target (if any),
    companions, with their kinds, source masks (if any), and trimaps and scribbles (if
    any)."""
    companions = submission["companions"]
    kinds = check_companion_kinds(submission.get("companion_kinds"), companions)
    textures = one_or_many(texture, "texture")
    files = [part("texture", source) for source in textures]
    if target is not None:
        files.append(part("target", target))
    files += _companion_parts(companions, len(textures))
    files += _mask_parts(source_mask, len(textures))
    files += mark_parts("trimap", marks, len(textures), "texture")
    files += mark_parts("scribbles", strokes, len(textures), "texture")
    document = {**size, **_given(submission["options"])}
    wait, idempotency_key = submission["wait"], submission["idempotency_key"]
    return _post(path, tuple(files), document, wait, idempotency_key, kinds)


def _mask_parts(
    source_mask: ImageSource | Sequence[ImageSource] | None, textures: int
) -> list[tuple[str, tuple[str, bytes, str]]]:
    """The ``source_mask`` parts: none, or one per texture in their order."""
    if source_mask is None:
        return []
    masks = _per_texture(source_mask, textures, "source_mask", "source_mask", "mask")
    return [part("source_mask", mask) for mask in masks]


#: A photo's trimap or scribbles: one image for one photo, else a sequence of one image (or
#: None, for a photo without) per photo, in order; None for none at all.
Marks = ImageSource | Sequence[ImageSource | None] | None


def mark_parts(
    field: str, marks: Marks, photos: int, of: str
) -> list[tuple[str, tuple[str, bytes, str]]]:
    """The ``trimap`` (or ``scribbles``) parts: none, or one per photo (``of``: a texture, a
    layer) in their order, an empty part standing for a photo without one; a
    :class:`ValidationError` of code ``invalid_trimap`` when their count is not the photos'.
    """
    if marks is None:
        return []
    items: list[ImageSource | None] = (
        list(marks) if isinstance(marks, (list, tuple)) else [cast(ImageSource, marks)]
    )
    if len(items) != photos:
        raise ValidationError(
            f"{field}: {len(items)} image(s) for {photos} {of}(s); give one per {of}, in their "
            f"order (None for a {of} without one)",
            code="invalid_trimap",
            field=field,
        )
    if all(item is None for item in items):
        return []
    # An empty file part: the service reads it as "no map for this photo".
    return [
        (field, ("none.png", b"", "image/png")) if item is None else part(field, item)
        for item in items
    ]


def _per_texture(
    sources: ImageSource | Sequence[ImageSource], textures: int, field: str, what: str, item: str
) -> list[ImageSource]:
    """``sources`` as a list of one ``item`` per texture (one alone stands for one texture's);
    a :class:`ValidationError` of code ``invalid_<field>`` when the count is not theirs."""
    items = one_or_many(sources, field)
    if len(items) != textures:
        raise ValidationError(
            f"{what}: {len(items)} {item}(s) for {textures} texture(s); give one {item} per "
            "texture, in the textures' order",
            code=f"invalid_{field}",
            field=field,
        )
    return items


def submit_request(
    texture: ImageSource | Sequence[ImageSource],
    *,
    width: int,
    height: int,
    source_mask: ImageSource | Sequence[ImageSource] | None = None,
    trimap: Marks = None,
    scribbles: Marks = None,
    **submission: Unpack[Submission],
) -> RequestSpec:
    """The ``POST /synthesize`` request.

    Parameters
    ----------
    texture : str, PathLike or bytes, or a sequence of them
        The sample texture (PNG or JPEG), or several examples of one texture, each sent as a
        ``texture`` part in order.
    width, height : int
        Output size in pixels.
    source_mask : str, PathLike or bytes, or a sequence of them, optional
        Masks whose black pixels are never used: one per texture, in their order (one image
        for one texture); each becomes a ``source_mask`` part.
    trimap, scribbles : str, PathLike or bytes, or a sequence of them (or None), optional
        The texture is an ordinary photo whose alpha the service extracts first: its trimap
        (or scribbles), or with several textures one per texture in their order (None for
        one without); each becomes a ``trimap`` (``scribbles``) part, an empty one for None.
    **submission
        ``companions``, ``companion_kinds``, ``options`` (synthesis options), ``wait`` and
        ``idempotency_key``: see :class:`Submission`.

    Returns
    -------
    RequestSpec

    Raises
    ------
    ValidationError
        A companion name or kind the service would reject, no texture, or companion maps or
        masks that are not one per texture (checked here to fail before uploading).
    OSError
        A path that cannot be read.
    """
    size = {"width": width, "height": height}
    return _quilt_request(
        "/synthesize", texture, None, size, submission, source_mask, trimap, scribbles
    )


def wang_request(
    texture: ImageSource | Sequence[ImageSource],
    *,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
) -> RequestSpec:
    """The ``POST /wang-tiles`` request: a complete set of Wang tiles.

    Parameters
    ----------
    texture : str, PathLike or bytes, or a sequence of them
        The sample texture (PNG or JPEG), or several examples of one texture, each sent as a
        ``texture`` part in order.
    options : Mapping
        Wang tile options (``WangOptions``); None values are left out so the service's
        defaults apply.
    wait, idempotency_key
        As for :func:`submit_request`.

    Returns
    -------
    RequestSpec

    Raises
    ------
    ValidationError
        No texture (checked here to fail before uploading).
    OSError
        A path that cannot be read.
    """
    files = tuple(part("texture", source) for source in one_or_many(texture, "texture"))
    return _post("/wang-tiles", files, _given(options), wait, idempotency_key)


def transfer_request(
    texture: ImageSource, target: ImageSource, **submission: Unpack[Submission]
) -> RequestSpec:
    """The ``POST /transfer`` request.

    Parameters
    ----------
    texture : str, PathLike or bytes
        The texture to render with (PNG or JPEG).
    target : str, PathLike or bytes
        The image to render (PNG or JPEG); the output has its size.
    **submission
        As for :func:`submit_request` (the options are transfer options, without a size).

    Returns
    -------
    RequestSpec

    Raises
    ------
    ValidationError, OSError
        As for :func:`submit_request`.
    TypeError
        No target (None).
    """
    if target is None:  # _quilt_request takes None as "no target part" (a synthesis)
        raise TypeError("transfer: target must be an image (a path or bytes), got None")
    return _quilt_request("/transfer", texture, target, {}, submission)


def matte_request(
    target: ImageSource,
    silhouette: ImageSource,
    layers: Sequence[ImageSource],
    *,
    normals: ImageSource | None,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
    trimap: Sequence[ImageSource | None] | None = None,
    scribbles: Sequence[ImageSource | None] | None = None,
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
    trimap, scribbles : sequence of (str, PathLike, bytes or None), optional
        One per layer, in their order: the trimap (scribbles) of a layer that is an ordinary
        photo, whose alpha the service extracts first; None for a layer taken as it is.
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
    images = images_of(layers, "layers")
    if not images:
        raise ValidationError(
            "layers: at least one texture is needed", code="missing_field", field="layer"
        )
    files = [part("target", target), part("silhouette", silhouette)]
    files += [part("layer", layer) for layer in images]
    if normals is not None:
        files.append(part("normals", normals))
    files += mark_parts("trimap", _layer_marks(trimap, "trimap"), len(images), "layer")
    files += mark_parts("scribbles", _layer_marks(scribbles, "scribbles"), len(images), "layer")
    return _post("/matte", tuple(files), _given(options), wait, idempotency_key)


def _layer_marks(marks: Sequence[ImageSource | None] | None, field: str) -> Marks:
    """A matte's maps: a sequence of one per layer (a single image is a mistake)."""
    if marks is not None and not isinstance(marks, (list, tuple)):
        raise TypeError(f"{field} is a list of one image (or None) per layer, not one image")
    return marks


def extract_request(
    photo: ImageSource,
    *,
    trimap: ImageSource | None,
    scribbles: ImageSource | None,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
) -> RequestSpec:
    """The ``POST /extract-alpha`` request: an RGBA texture from an ordinary photo.

    Parameters
    ----------
    photo : str, PathLike or bytes
        The photo (PNG or JPEG, gray or RGB: no alpha).
    trimap, scribbles : str, PathLike, bytes or None
        Of the photo's size: the trimap (white foreground, black background, grey unknown)
        and the scribbles (white and black strokes, the rest unknown); one at least.
    options : Mapping
        Alpha options (``AlphaOptions``: ``method``, ``foreground``); None values are left
        out so the service's defaults apply.
    wait, idempotency_key
        As for :func:`submit_request`.

    Returns
    -------
    RequestSpec
        The file parts in the order photo, trimap, scribbles.

    Raises
    ------
    ValidationError
        Neither a trimap nor scribbles (code ``invalid_trimap``, checked here to fail
        before uploading).
    OSError
        A path that cannot be read.
    """
    if trimap is None and scribbles is None:
        raise ValidationError(
            "extracting alpha needs a trimap or scribbles (or both)",
            code="invalid_trimap",
            field="trimap",
        )
    files = [part("photo", photo)]
    for name, given in (("trimap", trimap), ("scribbles", scribbles)):
        if given is not None:
            files.append(part(name, given))
    return _post("/extract-alpha", tuple(files), _given(options), wait, idempotency_key)


def fill_request(
    image: ImageSource,
    mask: ImageSource,
    *,
    texture: ImageSource | None,
    companions: Mapping[str, ImageSource] | None,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
) -> RequestSpec:
    """The ``POST /fill`` request: fill the pixels of an image that a mask marks.

    Parameters
    ----------
    image : str, PathLike or bytes
        The image to fill (PNG or JPEG); the output has its size.
    mask : str, PathLike or bytes
        The image's size: white (any colour above 0) where to fill, black where to keep.
    texture : str, PathLike, bytes or None
        Where the blocks come from instead of the image; None sends no ``texture`` part.
    companions : Mapping or None
        Companion maps of the image's size, filled the same way; each becomes a
        ``companion`` part named ``<name>.png``.
    options : Mapping
        Fill options (``FillOptions``); None values are left out so the service's defaults
        apply.
    wait, idempotency_key
        As for :func:`submit_request`.

    Returns
    -------
    RequestSpec
        The file parts in the order image, mask, texture, companions.

    Raises
    ------
    ValidationError
        A companion name the service would reject (checked here to fail before uploading).
    OSError
        A path that cannot be read.
    """
    files = [part("image", image), part("mask", mask)]
    if texture is not None:
        files.append(part("texture", texture))
    files += _companion_parts(companions)
    return _post("/fill", tuple(files), _given(options), wait, idempotency_key)


def extend_request(
    image: ImageSource,
    *,
    top: int,
    bottom: int,
    left: int,
    right: int,
    companions: Mapping[str, ImageSource] | None,
    options: Mapping[str, object],
    wait: float,
    idempotency_key: str | None,
) -> RequestSpec:
    """The ``POST /extend`` request: grow an image past its borders.

    Parameters
    ----------
    image : str, PathLike or bytes
        The image to extend (PNG or JPEG).
    top, bottom, left, right : int
        Pixels added on each side (checked by the service).
    companions : Mapping or None
        Companion maps of the image's size, extended the same way.
    options : Mapping
        The fill's options (``ExtendOptions``); None values are left out.
    wait, idempotency_key
        As for :func:`submit_request`.

    Returns
    -------
    RequestSpec

    Raises
    ------
    ValidationError, OSError
        As for :func:`fill_request`.
    """
    files = [part("image", image), *_companion_parts(companions)]
    margins = {"top": top, "bottom": bottom, "left": left, "right": right}
    document = {**margins, **_given(options)}
    return _post("/extend", tuple(files), document, wait, idempotency_key)


def tile_request(
    image: ImageSource,
    *,
    axes: str,
    band: int | None,
    blend: str | None = None,
    method: str | None = None,
    seed: int | None = None,
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
    method : str or None
        How the wraps are made seamless: ``"cut"`` or ``"fill"`` (checked by the service);
        None is left out: the service's default.
    seed : int or None
        The seed of ``method="fill"``; None is left out.
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
    files = (part("image", image),)
    document = _given({"axes": axes, "band": band, "blend": blend, "method": method, "seed": seed})
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


def manifest_request(job_id: str) -> RequestSpec:
    """``GET /jobs/{id}/manifest``: a Wang tile set's manifest."""
    return RequestSpec("GET", job_path(job_id, "manifest"))


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
