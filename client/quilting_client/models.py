"""The values the client returns: a job's status and the result of a synthesis, a transfer, a
matte, a fill, an extension or a Wang tile set.

They mirror the service's JSON and are deliberately forgiving: unknown keys are ignored and
missing optional keys take defaults, so a newer service does not break an older client.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["TERMINAL_STATES", "JobStatus", "SynthesisResult", "WangTilesResult"]

#: Job states after which the status never changes again.
TERMINAL_STATES = frozenset({"done", "failed", "cancelled"})


def _float(value: object, default: float | None = None) -> float | None:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return default


def _int(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _str(value: object) -> str | None:
    return value if isinstance(value, str) else None


def _mapping(value: object) -> dict[str, Any] | None:
    return dict(value) if isinstance(value, Mapping) else None


@dataclass(frozen=True)
class JobStatus:
    """The status of a job, as returned by ``GET /jobs/{id}``.

    Attributes
    ----------
    id : str
        The job id.
    status : str
        ``"queued"``, ``"running"``, ``"done"``, ``"failed"`` or ``"cancelled"``.
    progress : float
        Fraction done, 0 to 1.
    stage : str
        What the engine is doing (free text, for display).
    backend : str or None
        The cost backend that runs the job, once known.
    renderer : str or None
        What runs that backend: ``"cpu"`` or the GPU's GL renderer, once known.
    fallback : str or None
        Why the job left the GPU backend for ``fft`` while running, if it did.
    timings : Mapping[str, float]
        Seconds spent per stage.
    error : Mapping or None
        The problem document of a failed or cancelled job.
    width, height : int or None
        Size of the output, in pixels.
    companions : tuple of str
        Names of the companion maps quilted along; a matte job's are the maps it makes beside
        the result, ``("normals", "clusters")``.
    result, layout : str or None
        Paths of the result PNG and the layout JSON, once done; a matte job has no layout
        (its layers are quilted apart), so ``layout`` stays None. A Wang tile set's layout is
        its manifest.
    manifest : str or None
        Path of a Wang tile set's manifest JSON, once done; None for other jobs (and from
        services older than Wang tiles).
    created, started, finished : float or None
        Unix timestamps.
    stats : Mapping or None
        Statistics of the result, once done: a transfer's include ``correspondence_error``; a
        matte's are ``light`` (the unit vector used), ``albedo``, ``ambient_fit``,
        ``clusters``, ``patches`` and ``layer_size`` (``[width, height]``); a fill's and an
        extension's ``blocks``, ``filled_pixels`` and ``seam_error_mean``.
    operation : str
        ``"synthesize"``, ``"transfer"``, ``"matte"``, ``"fill"``, ``"extend"`` or
        ``"wang_tiles"``; ``"synthesize"`` when the service does not say (services older than
        transfer only synthesize).
    raw : Mapping
        The JSON object as received, unknown keys included (not compared, not shown).
    """

    id: str
    status: str
    progress: float = 0.0
    stage: str = ""
    backend: str | None = None
    renderer: str | None = None
    fallback: str | None = None
    # Mappings are left out of the hash so that the frozen dataclass stays hashable.
    timings: Mapping[str, float] = field(default_factory=dict, hash=False)
    error: Mapping[str, Any] | None = field(default=None, hash=False)
    width: int | None = None
    height: int | None = None
    companions: tuple[str, ...] = ()
    result: str | None = None
    layout: str | None = None
    created: float | None = None
    started: float | None = None
    finished: float | None = None
    stats: Mapping[str, Any] | None = field(default=None, hash=False)
    operation: str = "synthesize"
    manifest: str | None = None
    raw: Mapping[str, Any] = field(default_factory=dict, compare=False, hash=False, repr=False)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> JobStatus:
        """Build a status from the service's JSON object.

        Parameters
        ----------
        data : Mapping
            The decoded JSON object.

        Returns
        -------
        JobStatus

        Raises
        ------
        ValueError
            When ``data`` is not an object with a string ``id`` and ``status``.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"a job status is a JSON object, not {type(data).__name__}")
        job_id, status = data.get("id"), data.get("status")
        if not isinstance(job_id, str) or not isinstance(status, str):
            raise ValueError("a job status needs string 'id' and 'status' members")
        timings = _mapping(data.get("timings")) or {}
        companions = data.get("companions")
        return cls(
            id=job_id,
            status=status,
            progress=_float(data.get("progress"), 0.0) or 0.0,
            stage=_str(data.get("stage")) or "",
            backend=_str(data.get("backend")),
            renderer=_str(data.get("renderer")),
            fallback=_str(data.get("fallback")),
            timings={str(k): float(v) for k, v in timings.items() if _float(v) is not None},
            error=_mapping(data.get("error")),
            width=_int(data.get("width")),
            height=_int(data.get("height")),
            companions=tuple(str(c) for c in companions) if isinstance(companions, list) else (),
            result=_str(data.get("result")),
            layout=_str(data.get("layout")),
            created=_float(data.get("created")),
            started=_float(data.get("started")),
            finished=_float(data.get("finished")),
            stats=_mapping(data.get("stats")),
            operation=_str(data.get("operation")) or "synthesize",
            manifest=_str(data.get("manifest")),
            raw=dict(data),
        )

    @property
    def is_terminal(self) -> bool:
        """Whether the job has ended (done, failed or cancelled)."""
        return self.status in TERMINAL_STATES


class SynthesisResult(bytes):
    """The PNG bytes of a job's result (a synthesis, a transfer, a matte, a fill, an
    extension), with the job id and the companions.

    It *is* the result's ``bytes`` (write it to a file as is); the extra attributes carry what
    a caller that asked for companions needs.

    Parameters
    ----------
    image : bytes
        The result PNG.
    job_id : str or None
        The job that produced it.
    companions : Mapping[str, bytes] or None
        The companion PNGs by name: the quilted maps of a synthesis or a transfer, the filled
        (or extended) maps of a fill (or an extension), the ``normals`` and ``clusters`` maps
        of a matte (those asked for).
    extracted : sequence of (Mapping or None), optional
        When the service extracted an alpha from photos first (a trimap or scribbles was
        sent, or an :meth:`~quilting_client.Client.extract_alpha`): one entry per photo (the
        textures, the layers, the one photo), None for a photo without a map, each
        ``{"method", "foreground", "unknown", "iterations", "seconds"}`` (``unknown``: the
        share of the photo whose alpha was solved for). Empty otherwise.

    Attributes
    ----------
    job_id : str or None
    companions : dict[str, bytes]
    extracted : list of (dict or None)
    """

    job_id: str | None
    companions: dict[str, bytes]
    extracted: list[dict[str, Any] | None]

    def __new__(
        cls,
        image: bytes,
        *,
        job_id: str | None = None,
        companions: Mapping[str, bytes] | None = None,
        extracted: Sequence[Mapping[str, Any] | None] = (),
    ) -> SynthesisResult:
        self = super().__new__(cls, image)
        self.job_id = job_id
        self.companions = dict(companions or {})
        self.extracted = [None if entry is None else dict(entry) for entry in extracted]
        return self


class WangTilesResult(bytes):
    """The atlas PNG of a Wang tile set, with its manifest and the job id.

    It *is* the atlas's ``bytes`` (write it to a file as is), as :class:`SynthesisResult` is
    a result's.

    Parameters
    ----------
    atlas : bytes
        The atlas PNG: every tile, ``colors``^2 by ``colors``^2 of them, tile k at row
        k // ``colors``^2, column k % ``colors``^2.
    manifest : Mapping
        The ``quilting.wang`` manifest: ``tile``, ``colors``, ``rows``, ``columns``,
        ``edges`` and, for each tile of ``tiles``, its ``index``, ``x``, ``y`` in the atlas
        and its edge colours ``n``, ``e``, ``s``, ``w``.
    job_id : str or None
        The job that made it.

    Attributes
    ----------
    manifest : dict
    job_id : str or None
    """

    manifest: dict[str, Any]
    job_id: str | None

    def __new__(
        cls, atlas: bytes, *, manifest: Mapping[str, Any], job_id: str | None = None
    ) -> WangTilesResult:
        self = super().__new__(cls, atlas)
        self.manifest = dict(manifest)
        self.job_id = job_id
        return self

    def __getnewargs_ex__(self) -> tuple[tuple[bytes], dict[str, Any]]:
        # The manifest is a keyword __new__ needs: copy and pickle rebuild with it.
        return (bytes(self),), {"manifest": self.manifest, "job_id": self.job_id}

    @property
    def atlas(self) -> bytes:
        """The atlas PNG, as plain bytes."""
        return bytes(self)

    @property
    def tiles(self) -> list[dict[str, Any]]:
        """The manifest's tiles: ``index``, ``x``, ``y``, ``n``, ``e``, ``s``, ``w`` each."""
        found = self.manifest.get("tiles")
        return [dict(t) for t in found if isinstance(t, Mapping)] if isinstance(found, list) else []
