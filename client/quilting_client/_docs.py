"""The docstrings of the public methods, shared by ``Client`` and ``AsyncClient``.

Both clients have the same methods with the same arguments (the async ones are coroutines),
so each method's documentation is written once, here, and given to both by :func:`shared`, as
pandas' ``@doc`` decorator does: ``help(AsyncClient.synthesize)`` says as much as
``help(Client.synthesize)``. Sections that several methods have in common are written once
too.
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from typing import Any, TypeVar

from quilting_client._options import schemas

F = TypeVar("F", bound=Callable[..., Any])

_JOB_ID = """Parameters
----------
job_id : str
    The job."""

# What may go wrong once a job has been accepted and is being followed.
_FOLLOWED = """JobFailedError, JobCancelledError
    The job ended without a result; ``code`` and ``detail`` say why.
WaitTimeoutError
    ``timeout`` ran out first (the job keeps running).
ConnectionFailedError
    The service could not be reached."""

# What ``synthesize`` and ``transfer`` return and raise.
_RESULT_OR_ERRORS = f"""Returns
-------
SynthesisResult
    The result PNG (a ``bytes``), with ``job_id`` and the ``companions`` PNGs by name.

Raises
------
ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
    The service rejected the request (see :mod:`quilting_client.errors`).
{_FOLLOWED}"""


def _submission(job: str, method: str, arguments: str, status: str) -> str:
    """The docstring of a ``submit*`` method: ``method``'s job, submitted without waiting."""
    return f"""Submit {job} without waiting for it.

Parameters
----------
{arguments}
    As for :meth:`{method}`.

Returns
-------
JobStatus
    The new job's status (usually ``queued``{status}).
"""


#: The docstring of each public method, by name.
DOCSTRINGS: dict[str, str] = {
    "synthesize": f"""Synthesize a texture and return the result PNG.

Submits the job asking the service to hold the answer a little (up to 10 s, 1 s with a
progress callback); a job that finishes in that time comes back at once. Otherwise the
job is followed, through its event stream when ``progress`` is given (which is then
called on each progress event) or else by polling its status, honoring the service's
``Retry-After``; then the result is downloaded.

Parameters
----------
texture : str, os.PathLike or bytes, or a sequence of them
    The sample texture: a path to a PNG or JPEG file, or its bytes. A list (or tuple) is
    several examples of one texture (the same channels and bit depth, any sizes, each at
    least the block), sent as repeated ``texture`` parts in order: blocks are drawn from
    all of them, the best across them chosen (``weights``, one per texture in this order,
    prefers some; ``transforms`` adds their rotations and mirrors). One texture is sent
    and quilted exactly as before.
width, height : int
    Output size in pixels.
companions : Mapping[str, str | os.PathLike | bytes | sequence of them] or None
    Maps of the same size as the texture (normal, roughness...) to quilt with the same
    layout, by name (1 to 64 of ``A-Z a-z 0-9 _ -``). With several textures, each is a
    sequence of one map per texture, in their order, each of its texture's size.
companion_kinds : Mapping[str, str] or None
    How companions are rendered, by name: 'blend' (the default: blended like the
    result), 'hard' (never mixed: masks, material IDs; not with ``mode='walk'``),
    'normal' or 'normal_dx' (blended, then renormalized to unit vectors; 3 or 4 channels;
    OpenGL's green-up or DirectX's green-down normal maps, whose vectors turn with the
    blocks ``transforms`` rotates or mirrors). Sent as the ``companion_kinds`` form
    field; every name must be one of ``companions``.
source_mask : str, os.PathLike or bytes, or a sequence of them, or None
    An image of the texture's size whose black pixels are never used; with several
    textures, a sequence of one mask per texture, in their order (or None for none).
trimap, scribbles : str, os.PathLike or bytes, or a sequence of them (or None), or None
    The texture is an ordinary photo (gray or RGB, no alpha) of smoke, ice, leaves...: its
    trimap (white: surely the texture, black: surely background, grey: to be found) or
    scribbles (white and black strokes, the rest transparent or grey), of its size. The
    service extracts its alpha and foreground colour first (as :meth:`extract_alpha`; the
    ``matting`` option names the method) and alpha-quilts the RGBA texture. With several
    textures, a sequence of one per texture in their order, None for a texture without
    one. The result's ``extracted`` says how each alpha was found.
progress : callable or None
    ``progress(fraction, stage)``, called as the job advances.
poll_interval : float
    Seconds between status polls, at least.
timeout : float or None
    Seconds to wait for the job in all; None waits as long as it takes. When it runs
    out, :class:`WaitTimeoutError` is raised and the job is NOT cancelled: it keeps
    running on the service (cancel it with :meth:`cancel` if it is no longer wanted).
idempotency_key : str or None
    Sent as ``Idempotency-Key``: retrying with the same key and body gives the same job.
**options
    Any option of the service's ``SynthesizeOptions`` schema (its ``/openapi.json``;
    the client's copy, ``quilting_client/options.json``, lists them all: ``block``,
    ``blend``, ``tileable``, ``feather``, ``exclude_colors``...). None values are left
    to the service's defaults; the service refuses an unknown name.

{_RESULT_OR_ERRORS}
""",
    "submit": _submission(
        "a job",
        "synthesize",
        "texture, width, height, companions, companion_kinds, source_mask, trimap, "
        "scribbles, idempotency_key, **options",
        "",
    ),
    "transfer": f"""Render ``target`` in the texture of ``texture`` and return the result PNG.

Texture transfer (Efros & Freeman 2001, section 3): blocks of the texture are chosen
to match both their neighbours and the target under them. The output has the
target's size and the texture's channels. The job is submitted, followed and
downloaded as in :meth:`synthesize`.

Parameters
----------
texture : str, os.PathLike or bytes
    The texture to render with: a path to a PNG or JPEG file, or its bytes.
target : str, os.PathLike or bytes
    The image to render, likewise.
companions, companion_kinds, progress, poll_interval, timeout, idempotency_key
    As for :meth:`synthesize`; companions have the texture's size.
**options
    Any option of the service's ``TransferOptions`` schema (``alpha``,
    ``iterations``, ``correspondence``, ``shade``... with the synthesis options they
    share; all in ``quilting_client/options.json``). None values are left to the
    service's defaults.

{_RESULT_OR_ERRORS}
""",
    "submit_transfer": _submission(
        "a transfer job",
        "transfer",
        "texture, target, companions, companion_kinds, idempotency_key, **options",
        '; its ``operation`` is ``"transfer"``',
    ),
    "matte": f"""Lay textures on the surface of the object in ``target`` and return the result PNG.

Texture matting (the alpha quilting and texture matting paper, section 3): the
surface's normals and the light are read from the target's shading inside the
silhouette (or given), the surface is cut into patches, and each layer is quilted and
laid on every patch's plane, shaded by the light, bottom layer first. The output has
the target's size. The job is submitted, followed and downloaded as in
:meth:`synthesize`.

Parameters
----------
target : str, os.PathLike or bytes
    The image with the object: a path to a PNG or JPEG file, or its bytes.
silhouette : str, os.PathLike or bytes
    The target's size: white (or opaque) where the surface is, black elsewhere.
layers : sequence of str, os.PathLike or bytes
    The textures to lay on the surface, bottom first (opaque ones first, then RGBA
    ones, which are alpha-quilted); at least one. A single image goes in a list.
normals : str, os.PathLike, bytes or None
    A normal map of the target's size (``(n + 1) / 2`` colours, +y up) to use instead
    of the one read from the shading.
trimap, scribbles : sequence of (str, os.PathLike, bytes or None), or None
    One per layer, in the layers' order: the trimap (or scribbles) of a layer that is an
    ordinary photo (no alpha), whose alpha and foreground colour the service extracts
    first (the ``matting`` option) before alpha-quilting it; None for a layer taken as
    it is. The result's ``extracted`` says how each alpha was found.
companions : iterable of str
    The maps made beside the result to download into the result's ``companions``:
    ``"normals"`` (the normals used, as a normal map) and ``"clusters"`` (the patches
    in distinct colours). None by default; :meth:`result` fetches them later too.
progress, poll_interval, timeout, idempotency_key
    As for :meth:`synthesize`.
**options
    Matte options: ``clusters``, ``light`` (``(x, y, z)`` with z > 0, towards the
    light: x right, y up, z towards the viewer), ``smoothing``, ``min_z``,
    ``spatial_weight``, ``scale``, ``ambient``, and the quilting options applied to
    every layer: ``block``, ``overlap``, ``tolerance``, ``mode``, ``seed``,
    ``backend``, ``min_candidates``, ``error``, ``discard``, ``exclude_colors``,
    ``histogram_weight``, ``epsilon``, ``eta``. None values are left to the service's
    defaults (``light=None``: estimated from the shading).

Returns
-------
SynthesisResult
    The result PNG (a ``bytes``), with ``job_id`` and the ``companions`` asked for by
    name. The job's status (:meth:`status`) has ``operation`` ``"matte"`` and, in its
    ``stats``, the ``light`` used, ``albedo``, ``ambient_fit``, ``clusters``,
    ``patches`` and ``layer_size``.

Raises
------
ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
    The service rejected the request (HTTP 422: code ``invalid_parameter`` with the
    option in ``field``, ``invalid_image`` for a silhouette or normal map not of the
    target's size, ``too_many_layers``...); or, before anything is sent, no layer
    (code ``missing_field``) or a companion name the service cannot have.
{_FOLLOWED}
TypeError
    ``layers`` is a single image, or ``companions`` a single name, not a collection.
""",
    "submit_matte": _submission(
        "a matte job",
        "matte",
        "target, silhouette, layers, normals, trimap, scribbles, idempotency_key, **options",
        '; its ``operation`` is ``"matte"`` and its\n    ``companions`` are ``("normals", '
        '"clusters")``, fetched with :meth:`result`',
    ),
    "fill": f"""Fill the pixels of ``image`` that ``mask`` marks and return the result PNG.

Removes an object, a stain, a logo: the hole is covered by overlapping blocks placed
from its border inward, each chosen among the blocks of the image outside the hole (or
of ``texture``) by its error over every known pixel under it and joined to them along a
minimum cut (Efros & Freeman 2001; Kwatra et al. 2003, graph-cut seams). Every pixel
outside the mask comes back as it was, byte for byte, at the image's bit depth. The
job is submitted, followed and downloaded as in :meth:`synthesize`.

Parameters
----------
image : str, os.PathLike or bytes
    The image to fill: a path to a PNG or JPEG file, or its bytes. The output has its
    size, channels and bit depth.
mask : str, os.PathLike or bytes
    The image's size: white (any colour above 0) where to fill, black where to keep; with
    alpha, a transparent pixel is kept. Prefer PNG (JPEG's noise marks pixels). An empty
    mask gives the image back.
texture : str, os.PathLike, bytes or None
    Take the blocks from this texture instead of the image (it must have the image's
    channels and bit depth); needed when the mask covers the whole image.
companions : Mapping[str, str | os.PathLike | bytes] or None
    Maps of the image's size (normal, roughness...) to fill the same way, by name: each
    filled pixel is copied from where the image's came from. Not with ``texture``.
progress, poll_interval, timeout, idempotency_key
    As for :meth:`synthesize`.
**options
    Any option of the service's ``FillOptions`` schema (``block``, ``overlap``,
    ``blend``, ``seed``...; all in ``quilting_client/options.json``). None values are
    left to the service's defaults.

Returns
-------
SynthesisResult
    The result PNG (a ``bytes``), with ``job_id`` and the ``companions`` PNGs by name.
    The job's status (:meth:`status`) has ``operation`` ``"fill"`` and, in its
    ``stats``, ``blocks``, ``filled_pixels`` and ``seam_error_mean``; a fill has no
    layout.

Raises
------
ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
    The service rejected the request (HTTP 422: code ``invalid_image`` with ``field``
    ``"mask"`` for a mask of another size or one covering the whole image without a
    texture, ``invalid_parameter`` with ``field`` ``"block"`` for a block that fits
    nowhere outside the hole (the detail names the largest that does),
    ``job_too_large``...).
{_FOLLOWED}
""",
    "submit_fill": _submission(
        "a fill job",
        "fill",
        "image, mask, texture, companions, idempotency_key, **options",
        '; its ``operation`` is ``"fill"``',
    ),
    "extend": f"""Grow ``image`` past its borders and return the result PNG (uncrop).

A canvas larger by ``top``, ``bottom``, ``left`` and ``right`` pixels (see Other
Parameters; 0 by default), the image placed on it unchanged, byte for byte, and the
added border synthesized from the image as :meth:`fill` fills a hole. The job is
submitted, followed and downloaded as in :meth:`synthesize`.

Parameters
----------
image : str, os.PathLike or bytes
    The image to extend: a path to a PNG or JPEG file, or its bytes.
companions : Mapping[str, str | os.PathLike | bytes] or None
    Maps of the image's size to extend the same way, by name.
progress, poll_interval, timeout, idempotency_key
    As for :meth:`synthesize`.
**options
    Any other option of the service's ``ExtendOptions`` schema: the fill's (``block``,
    ``blend``, ``seed``...; all in ``quilting_client/options.json``). None values are
    left to the service's defaults.

Returns
-------
SynthesisResult
    The result PNG, of (width + left + right) x (height + top + bottom), with
    ``job_id`` and the ``companions`` PNGs by name. The job's ``operation`` is
    ``"extend"``.

Raises
------
ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
    The service rejected the request (HTTP 422: ``invalid_parameter`` naming the margin
    for an extension past the output limits or the block for one larger than the image,
    ``job_too_large``...).
{_FOLLOWED}
""",
    "submit_extend": _submission(
        "an extend job",
        "extend",
        "image, top, bottom, left, right, companions, idempotency_key, **options",
        '; its ``operation`` is ``"extend"``',
    ),
    "extract_alpha": f"""Extract the alpha of an ordinary photo and return the RGBA texture PNG.

The first step of alpha quilting (the alpha quilting and texture matting paper, section
2): the user says which parts of a photo of smoke, ice or leaves are surely the texture and
surely background, a matting solver finds the alpha in between (closed-form matting,
Levin, Lischinski and Weiss 2008, or the others of ``method``), and the foreground colour
is estimated under it so that the background showing through does not stay in the
texture. The result has the photo's size and bit depth, ready for ``mode='alpha'`` of
:meth:`synthesize` or a :meth:`matte` layer (which also take the photo and its trimap
directly). The job is submitted, followed and downloaded as in :meth:`synthesize`.

Parameters
----------
photo : str, os.PathLike or bytes
    The photo: a path to a PNG or JPEG file, or its bytes; gray or RGB (no alpha).
trimap : str, os.PathLike, bytes or None
    Of the photo's size: white where the photo is surely the texture, black where surely
    background, grey (any other colour) where the alpha is to be found.
scribbles : str, os.PathLike, bytes or None
    Of the photo's size: a few white (texture) and black (background) strokes, the rest
    transparent or grey; drawn over the trimap when both come. One of the two is needed.
progress, poll_interval, timeout, idempotency_key
    As for :meth:`synthesize`.
**options
    ``method`` ('lkm', the default: large-kernel matting; 'cf': closed-form matting;
    'knn': KNN matting) and ``foreground`` ('ml', the default: the estimated foreground
    colour; 'photo': the photo's own colour), the service's ``AlphaOptions``.

Returns
-------
SynthesisResult
    The RGBA PNG (a ``bytes``), with ``job_id`` and ``extracted``: one entry,
    ``{{"method", "foreground", "unknown", "iterations", "seconds"}}``.

Raises
------
ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
    The service rejected the request (HTTP 422: code ``invalid_trimap`` with ``field``
    ``"trimap"`` or ``"scribbles"`` for a map of another size or marking no foreground or
    no background, ``invalid_image`` for a photo that already has alpha,
    ``job_too_large``; HTTP 503 ``matting_unavailable`` for a service without the
    matting extra); or, before anything is sent, neither a trimap nor scribbles (code
    ``invalid_trimap``).
{_FOLLOWED}
""",
    "submit_extract_alpha": _submission(
        "an alpha extraction",
        "extract_alpha",
        "photo, trimap, scribbles, idempotency_key, **options",
        '; its ``operation`` is ``"extract_alpha"``',
    ),
    "wang_tiles": f"""Make a complete set of Wang tiles and return its atlas, with its manifest.

Every edge of a tile carries one of ``colors`` colours, and the set has a tile for
every combination (``colors``^4 tiles; Cohen, Shade, Hiller and Deussen 2003): two
tiles whose touching edges share a colour meet seamlessly, pixel for pixel, so any
arrangement that keeps that rule tiles the plane (drawn at random, it never repeats).
Each colour is a diamond of texture quilted from the examples, each tile four diamond
halves joined along minimum cuts. The job is submitted to ``POST /wang-tiles`` and
followed as in :meth:`synthesize`; the atlas is its result and the manifest
(``GET /jobs/{{id}}/manifest``) is downloaded after it.

Parameters
----------
texture : str, os.PathLike or bytes, or a sequence of them
    The sample texture (a path to a PNG or JPEG file, or its bytes), or several examples
    of one texture, as for :meth:`synthesize`.
progress, poll_interval, timeout, idempotency_key
    As for :meth:`synthesize`.
**options
    Any option of the service's ``WangOptions`` schema (``colors``, ``tile``, ``block``,
    ``blend``, ``transforms``, ``weights``, ``seed``...; all in
    ``quilting_client/options.json``). None values are left to the service's defaults.

Returns
-------
WangTilesResult
    The atlas PNG (a ``bytes``, also ``atlas``): ``colors``^2 by ``colors``^2 tiles of
    ``tile`` pixels, tile k at row k // ``colors``^2, column k % ``colors``^2; its
    ``manifest`` (a dict: ``tile``, ``colors``, ``rows``, ``columns``, ``edges`` and, for
    each of its ``tiles``, ``index``, ``x``, ``y`` in the atlas and the edge colours
    ``n``, ``e``, ``s``, ``w``) and ``job_id``.

Raises
------
ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
    The service rejected the request (HTTP 422: ``invalid_parameter`` naming the option,
    e.g. an odd ``tile``, ``colors`` out of 2..4, ``weights`` not one per texture, an
    atlas past the output limits; ``too_many_textures``; ``job_too_large``...).
{_FOLLOWED}
""",
    "submit_wang_tiles": _submission(
        "a Wang tile set's job",
        "wang_tiles",
        "texture, idempotency_key, **options",
        '; its ``operation`` is ``"wang_tiles"``; the atlas is its\n    '
        "result (:meth:`result`), the manifest :meth:`manifest`",
    ),
    "tile": """Make an existing image repeat seamlessly and return the tileable PNG.

The image keeps its size, bit depth and centre: only bands along its borders are
replaced, inside minimum-error cuts, by the image rolled by half its size (or, with
``method="fill"``, the bands across the wraps are synthesized again from the rest of the
image). The service answers at once with the PNG (``POST /tile``); no job is created, so
there is no job id, progress or companion.

Parameters
----------
image : str, os.PathLike or bytes
    The image: a path to a PNG or JPEG file, or its bytes. Each tiled side at least 4
    pixels.
axes : str
    Which wraps must be seamless: ``"both"``, ``"x"`` (the last column joins the first)
    or ``"y"`` (the last row joins the first).
band : int or None
    Width in pixels of each border band the cuts may wander in, 1..side / 2 - 1; None
    leaves the service's default, a quarter of each side.
blend : str or None
    How the cuts are joined: ``"none"``, as they are (every pixel an input pixel), or
    ``"poisson"``, blended in the gradient domain so that a brightness gradient across
    the photo does not show as steps along them; None leaves the service's default
    (``"poisson"``).
method : str or None
    How the wraps are made seamless: ``"cut"`` (minimum-error cuts, every pixel an
    input pixel) or ``"fill"`` (the band across each wrap synthesized again by filling);
    None leaves the service's default (``"cut"``).
seed : int or None
    The random seed of ``method="fill"``; None leaves the service's default.
timeout : float or None
    Seconds allowed to connect, send and wait for each read of the answer, in place of
    the client's ``timeout``; None keeps the client's. When it runs out,
    :class:`ConnectionFailedError` is raised.

Returns
-------
bytes
    The tileable PNG, of the image's size.

Raises
------
ValidationError
    An option or the image was rejected (HTTP 422; ``code`` ``invalid_parameter`` and
    ``field`` ``"band"`` for a band too wide, ``invalid_image``, ``image_too_large``...).
PayloadTooLargeError, UnsupportedMediaTypeError, AuthenticationError
    The service refused the upload (HTTP 413, 415, 401).
ServiceUnavailableError
    The service is draining (HTTP 503); ``retry_after`` says when to try again.
ConnectionFailedError
    The service could not be reached, or ``timeout`` ran out.
ValueError
    ``timeout`` is not positive.
""",
    "status": f"""The status of a job.

{_JOB_ID}

Returns
-------
JobStatus
""",
    "result": f"""The result PNG of a finished job, or one of its quilted companions.

{_JOB_ID}
name : str or None
    A companion's name (those of the job's status: a matte job's are ``"normals"``
    and ``"clusters"``); None for the result itself.

Returns
-------
bytes
    The PNG.

Raises
------
ConflictError
    The job is not done (code ``job_not_done``, ``job_failed``, ``job_cancelled``).
GoneError
    The results were evicted.
""",
    "layout": f"""The layout document of a finished job (which block went where).

{_JOB_ID}

Returns
-------
dict

A synthesis made from several examples records each block's example and transform
(version 3, ``sources``); a Wang tile set's layout is its manifest (see
:meth:`manifest`).

Raises
------
NotFoundError
    The job has no layout: a matte job's layers are quilted apart (code ``no_layout``).
""",
    "manifest": f"""The manifest of a finished Wang tile set's job (each tile's place and edges).

{_JOB_ID}

Returns
-------
dict
    The ``quilting.wang`` document: ``tile``, ``colors``, ``rows``, ``columns``,
    ``edges`` (``["n", "e", "s", "w"]``), ``tiles`` (each ``index``, ``x``, ``y`` in the
    atlas, ``n``, ``e``, ``s``, ``w``) and ``meta`` (the options that made it).

Raises
------
NotFoundError
    The job is not a Wang tile set's (code ``no_manifest``).
ConflictError
    The job is not done (code ``job_not_done``, ``job_failed``, ``job_cancelled``).
GoneError
    The results were evicted.
""",
    "cancel": f"""Ask for a job to be cancelled.

{_JOB_ID}

Returns
-------
JobStatus
    Its status; ``cancelled`` at once for a queued job, later for a running one.

Raises
------
ConflictError
    The job had already ended (code ``job_finished``).
""",
    "events": f"""The job's server-sent events, as they come, until the service ends the stream.

{_JOB_ID}

Yields
------
tuple of (str, dict)
    ``("progress", {{"progress", "stage", "status"}})`` events, then one terminal
    ``("done" | "failed" | "cancelled", <job status JSON>)``.
""",
    "wait": f"""Wait for a job to end.

{_JOB_ID}
progress : callable or None
    ``progress(fraction, stage)``; given, the event stream is followed instead of
    polling.
timeout : float or None
    Seconds to wait; None waits as long as it takes. The job is NOT cancelled when
    it runs out.
poll_interval : float
    Seconds between status polls, at least.

Returns
-------
JobStatus
    The final status of the job, which is ``done``.

Raises
------
JobFailedError, JobCancelledError
    The job ended without a result (the error's ``job`` is its final status).
WaitTimeoutError
    ``timeout`` ran out first.
""",
    "health": """Whether the service is up (``GET /healthz``); False if it cannot be reached.

Returns
-------
bool
""",
    "ready": """The service's readiness (``GET /readyz``): backend, queue depth, workers.

Returns
-------
dict
    ``status``, ``queue``, ``backend``, ``renderer``, ``backend_reason``, ``queue_depth``,
    ``running``, ``workers``, and ``matting``: whether the service can extract alpha
    (:meth:`extract_alpha`, a ``trimap`` beside a texture).

Raises
------
ServiceUnavailableError
    The service is draining or its queue is full (code ``draining`` / ``queue_full``).
""",
}


#: The service operation whose options a method takes as ``**options``.
OPTIONS_OF = {
    "synthesize": "synthesize",
    "submit": "synthesize",
    "transfer": "transfer",
    "submit_transfer": "transfer",
    "matte": "matte",
    "submit_matte": "matte",
    "fill": "fill",
    "submit_fill": "fill",
    "extend": "extend",
    "submit_extend": "extend",
    "wang_tiles": "wang_tiles",
    "submit_wang_tiles": "wang_tiles",
    "extract_alpha": "extract_alpha",
    "submit_extract_alpha": "extract_alpha",
}

#: JSON schema types as Python names them.
_PYTHON_TYPES = {
    "integer": "int",
    "number": "float",
    "boolean": "bool",
    "string": "str",
    "array": "list",
    "null": "None",
}


def options_section(operation: str) -> str:
    """The numpydoc "Other Parameters" section of ``operation``'s options, from the service's
    schema (``options.json``): every option a method's ``**options`` passes on, with the
    service's own description, so the client's documentation cannot fall behind it."""
    lines = ["Other Parameters", "----------------"]
    for name, schema in schemas()[operation].items():
        if name in ("width", "height"):  # keywords of their own
            continue
        lines.append(f"{name} : {_kind(schema)}")
        text = schema.get("description", "")
        lines += textwrap.wrap(text, 84, initial_indent="    ", subsequent_indent="    ")
    return "\n".join(lines) + "\n"


def _kind(schema: dict[str, Any]) -> str:
    """An option's type as numpydoc writes it: its choices as a set, else its type."""
    if "anyOf" in schema:
        return " or ".join(_kind(part) for part in schema["anyOf"])
    if "enum" in schema:
        return "{" + ", ".join(repr(value) for value in schema["enum"]) + "}"
    return _PYTHON_TYPES.get(schema.get("type", ""), "object")


def shared(method: F) -> F:
    """Give a public method of a client its docstring from :data:`DOCSTRINGS` (and, for a
    method that takes ``**options``, the options' section made by :func:`options_section`).

    Parameters
    ----------
    method : callable
        A method of ``Client`` or ``AsyncClient``, looked up by its name.

    Returns
    -------
    callable
        ``method`` itself (a coroutine function stays one), its ``__doc__`` set.
    """
    doc = DOCSTRINGS[method.__name__]
    operation = OPTIONS_OF.get(method.__name__)
    method.__doc__ = doc if operation is None else doc + "\n" + options_section(operation)
    return method
