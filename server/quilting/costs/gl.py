"""The GPU backend: cost fields by direct SSD in GLSL compute shaders (moderngl).

The only module that imports moderngl. Per wavefront level, three dispatches and two small
readbacks: ``cost_field.comp`` computes every candidate's cost (one dispatch, block index in
z) and the minimum of each run of candidates; ``kth_bound.comp`` reduces those minima on the
GPU, by a radix select, to an upper bound U of the k-th best cost; ``shortlist.comp`` appends
every candidate within the tolerance of U to one list. Only that list (and U) is read back;
the engine re-scores the near-ties exactly, so ``gl``, ``fft`` and ``reference`` choose the
same blocks.

The device's limits (storage-buffer size, work-group count, size and invocations, shared
memory) are read once per context into :attr:`GLInfo.limits`: a level is split into chunks
whose buffers fit, work groups shrink where a device allows fewer invocations, and what cannot
fit is a :class:`BackendError` that names the limit. ``ctx.error`` is checked after every
upload, dispatch and readback, and an error names the step.

GL contexts are bound to the thread that made them, so one daemon thread per process (and
device) owns the context and runs every GL call; backends hand it closures. A GL failure
(a limit exceeded, a compile or driver error, ``ctx.error`` set) is a :class:`BackendError`.
"""

from __future__ import annotations

import ctypes
import functools
import glob
import importlib.resources
import os
import queue
import re
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, TypeVar

import moderngl
import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import BackendError
from quilting.core.fields import CostRequest, FieldBatch, Shortlist, find_mask
from quilting.core.select import shortlist_fields
from quilting.costs.variables import GL_DEVICE_VARIABLE

T = TypeVar("T")

#: Unit round-off of float32.
_EPS32 = 2.0**-24
#: Candidates per invocation of cost_field.comp (the register tile) and its work group shape.
RUN = 8
LOCAL_X, LOCAL_Y = 16, 4
#: Work-group size of the reduction and compaction kernels (smaller on a device that allows
#: fewer invocations).
LOCAL_REDUCE = 256
#: Shared memory of kth_bound.comp: a 256-bin histogram, 16 partial sums and three words.
KTH_SHARED_BYTES = (256 + 16 + 3) * 4
#: ``GL_MAX_COMPUTE_SHARED_MEMORY_SIZE``, which moderngl's ``ctx.info`` does not report, and
#: the least a GL 4.3 device may report for it (assumed when it cannot be read).
_GL_MAX_COMPUTE_SHARED_MEMORY_SIZE = 0x8262
MIN_SHARED_BYTES = 32768
#: Largest field buffer of one dispatch, besides the driver's own limit.
MAX_FIELD_BYTES = 256 << 20
#: Most shortlist entries one dispatch may append before the host reads the dense field.
MAX_ENTRIES = 1 << 20
#: Software rasterizers: they run the shaders, but far slower than the CPU FFT.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "software rasterizer")
#: How the device is chosen (EGL device index).
DEVICE_VARIABLE = GL_DEVICE_VARIABLE


@dataclass(frozen=True)
class GLInfo:
    """What the context reports about the device."""

    renderer: str
    vendor: str
    version: str
    limits: dict[str, Any] = field(default_factory=dict)

    @property
    def software(self) -> bool:
        """True for a CPU rasterizer such as Mesa llvmpipe."""
        return any(name in self.renderer.lower() for name in SOFTWARE_RENDERERS)


def device_index() -> int:
    """The EGL device index to use (``QUILTING_GL_DEVICE``, default 0)."""
    raw = os.environ.get(DEVICE_VARIABLE, "0")
    try:
        index = int(raw)
    except ValueError:
        raise BackendError(f"{DEVICE_VARIABLE} must be a device index >= 0, got {raw!r}") from None
    if index < 0:
        raise BackendError(f"{DEVICE_VARIABLE} must be a device index >= 0, got {raw!r}")
    return index


def gpu_device_nodes() -> list[str]:
    """Device files of hardware GPUs (``/dev/nvidia*``, ``/dev/dri/renderD*``).

    Without one there is no hardware GPU to find, and ``auto`` need not create a context.
    """
    return sorted(glob.glob("/dev/nvidia[0-9]*") + glob.glob("/dev/dri/renderD*"))


class _Owner:
    """The thread that owns one GL context and runs every call made on it."""

    def __init__(self, index: int) -> None:
        self._calls: queue.SimpleQueue[tuple[Callable[[Any], Any], Future[Any]]] = (
            queue.SimpleQueue()
        )
        started: Future[GLInfo] = Future()
        self._thread = threading.Thread(
            target=self._main, args=(index, started), name=f"quilting-gl-{index}", daemon=True
        )
        self.programs: dict[tuple[str, tuple[tuple[str, int], ...]], Any] = {}  # GL thread only
        self._thread.start()
        self.info = started.result()  # raises BackendError if no context could be made

    def _main(self, index: int, started: Future[GLInfo]) -> None:
        try:
            settings: dict[str, Any] = {"backend": "egl", "device_index": index}
            ctx = moderngl.create_context(standalone=True, require=430, **settings)
        except Exception as exc:  # any driver failure means "no context"
            started.set_exception(
                BackendError(f"no OpenGL 4.3 context on EGL device {index}: {exc}".strip())
            )
            return
        info = ctx.info
        limits = {
            "max_ssbo_bytes": int(info["GL_MAX_SHADER_STORAGE_BLOCK_SIZE"]),
            "max_groups": tuple(int(n) for n in info["GL_MAX_COMPUTE_WORK_GROUP_COUNT"]),
            "max_group_size": tuple(int(n) for n in info["GL_MAX_COMPUTE_WORK_GROUP_SIZE"]),
            "max_invocations": int(info["GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS"]),
            "max_shared_bytes": _shared_memory_limit(ctx),
        }
        started.set_result(
            GLInfo(
                renderer=str(info["GL_RENDERER"]),
                vendor=str(info["GL_VENDOR"]),
                version=str(info["GL_VERSION"]),
                limits=limits,
            )
        )
        while True:
            call, future = self._calls.get()
            if not future.set_running_or_notify_cancel():
                continue
            try:
                future.set_result(call(ctx))
            except BaseException as exc:  # handed to the caller
                future.set_exception(exc)

    def run(self, call: Callable[[Any], T]) -> T:
        """Run ``call(ctx)`` on the owning thread and return its result (or raise its error)."""
        future: Future[T] = Future()
        self._calls.put((call, future))
        return future.result()


def _shared_memory_limit(ctx: Any) -> int:
    """``GL_MAX_COMPUTE_SHARED_MEMORY_SIZE`` of the current context (GL thread only).

    moderngl does not report it, so ``glGetIntegerv`` is called through
    ``eglGetProcAddress`` (the context is an EGL one). Where that fails, the least any GL 4.3
    device reports (:data:`MIN_SHARED_BYTES`) is assumed: the kernels then stay within it.
    """
    try:
        egl = ctypes.CDLL("libEGL.so.1")
        egl.eglGetProcAddress.restype = ctypes.c_void_p
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        address = egl.eglGetProcAddress(b"glGetIntegerv")
        if not address:
            return MIN_SHARED_BYTES
        prototype = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.POINTER(ctypes.c_int))
        value = ctypes.c_int(-1)
        prototype(address)(_GL_MAX_COMPUTE_SHARED_MEMORY_SIZE, ctypes.byref(value))
    except (OSError, AttributeError):
        return MIN_SHARED_BYTES
    error = ctx.error  # read (and so cleared) here, not blamed on the first dispatch
    return value.value if error == "GL_NO_ERROR" and value.value > 0 else MIN_SHARED_BYTES


_owners: dict[int, _Owner | BackendError] = {}
_owners_lock = threading.Lock()


def _owner(index: int) -> _Owner:
    """The process's context on EGL device ``index``, made once (failures are remembered)."""
    with _owners_lock:
        known = _owners.get(index)
        if known is None:
            try:
                known = _Owner(index)
            except BackendError as exc:
                known = exc
            _owners[index] = known
    if isinstance(known, BackendError):
        raise known
    return known


def probe(index: int | None = None) -> GLInfo:
    """Make (or reuse) the context and describe its device; :class:`BackendError` if none."""
    return _owner(device_index() if index is None else index).info


#: The storage-buffer binding point of each of a job's buffers, by its name in
#: ``GLBackend._buffers``. Written once, here: every shader gets them as ``BINDING_<NAME>``
#: defines, and the backend binds through :meth:`GLBackend._bound`.
BINDINGS: dict[str, int] = {
    "source": 0,
    "guide": 1,
    "templates": 2,
    "previous": 3,
    "guides": 4,
    "masks": 5,
    "spans": 6,
    "requests": 7,
    "field": 8,
    "minima": 9,
    "header": 11,
    "entries": 12,
}

#: A line of a shader that stands for a shared piece of ``shaders/`` (GLSL has no include).
_INCLUDE = re.compile(r'^#include "([\w.]+)"$', re.MULTILINE)


def shader_source(name: str, defines: dict[str, int]) -> str:
    """GLSL source of ``shaders/<name>`` with ``#version 430``, the given ``#define``s and the
    buffers' binding slots (:data:`BINDINGS`), its ``#include "piece.glsl"`` lines replaced by
    those files of ``shaders/``."""
    files = importlib.resources.files("quilting.shaders")
    text = _INCLUDE.sub(
        lambda match: files.joinpath(match.group(1)).read_text("utf-8"),
        files.joinpath(name).read_text("utf-8"),
    )
    slots = {f"BINDING_{buffer.upper()}": slot for buffer, slot in BINDINGS.items()}
    lines = "".join(f"#define {k} {v}\n" for k, v in {**defines, **slots}.items())
    return "#version 430\n" + lines + text


SHADERS = ("cost_field.comp", "kth_bound.comp", "shortlist.comp")


def _mib(size: int) -> str:
    return f"{size / 2**20:.3g} MiB"


def _check(ctx: Any, what: str) -> None:
    error = ctx.error
    if error != "GL_NO_ERROR":
        raise BackendError(f"OpenGL reported {error} during {what}")


@dataclass
class _Masks:
    """The job's distinct masks, their row spans and non-zero counts, as uploaded."""

    arrays: list[NDArray[np.float32]] = field(default_factory=list)
    nonzero: list[int] = field(default_factory=list)


class GLBackend:
    """Cost fields from GLSL compute shaders on the process's GL context.

    Parameters
    ----------
    device : int, optional
        EGL device index; default ``QUILTING_GL_DEVICE`` or 0.
    """

    name = "gl"

    def __init__(self, device: int | None = None) -> None:
        self._owner = _owner(device_index() if device is None else device)
        self.info = self._owner.info
        self.renderer = self.info.renderer
        self._block = 0
        self._channels = 0
        self._guide_channels = 0
        self._source_shape = (0, 0)
        self._field_shape = (0, 0)
        self._masks = _Masks()
        self._buffers: dict[str, Any] = {}

    # -- host side ---------------------------------------------------------------------------

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        height, width, channels = source.shape
        if channels not in (1, 3, 4):
            raise BackendError(f"the gl backend takes 1, 3 or 4 channels, got {channels}")
        if guide is not None and not 1 <= guide.shape[2] <= 4:
            raise BackendError(f"the gl backend takes 1..4 guide channels, got {guide.shape[2]}")
        self._block = block
        self._channels = channels
        self._guide_channels = 0 if guide is None else guide.shape[2]
        self._source_shape = (height, width)
        self._field_shape = (height - block + 1, width - block + 1)
        self._masks = _Masks()
        limit = self.info.limits["max_ssbo_bytes"]
        for what, image in (("texture", source), ("guide map", guide)):
            if image is not None and image.nbytes > limit:
                raise BackendError(
                    f"the {what} ({width}x{height}, {image.shape[2]} channels as float32, "
                    f"{_mib(image.nbytes)}) exceeds this GPU's storage-buffer limit of "
                    f"{_mib(limit)}"
                )
        if self._per_request_bytes() > min(limit, MAX_FIELD_BYTES):
            raise BackendError(
                f"one cost field ({self._field_shape[1]}x{self._field_shape[0]} candidates) "
                f"exceeds the storage-buffer limit of {_mib(min(limit, MAX_FIELD_BYTES))}"
            )
        src = np.ascontiguousarray(source, dtype=np.float32)
        gmap = None if guide is None else np.ascontiguousarray(guide, dtype=np.float32)
        self._owner.run(lambda ctx: self._upload(ctx, src, gmap))

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        values: list[NDArray[np.float32]] = []
        bounds: list[NDArray[np.float64]] = []
        for chunk in self._chunks(requests):
            staged = self._stage(chunk)
            dense = self._run(functools.partial(self._dispatch, staged=staged, select=None)).dense
            assert dense is not None
            top = dense.reshape(staged.n, -1).max(axis=1).astype(np.float64)
            values.append(dense.reshape(staged.n, *self._field_shape))
            bounds.append(staged.rel * top + staged.absolute)
        height, width = self._field_shape
        if not values:
            return FieldBatch(np.zeros((0, height, width), np.float32), np.zeros(0))
        return FieldBatch(np.concatenate(values), np.concatenate(bounds))

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        result: list[Shortlist] = []
        for chunk in self._chunks(requests):
            result.extend(self._run_shortlist(chunk, tolerance, min_candidates))
        return result

    def close(self) -> None:
        buffers, self._buffers = self._buffers, {}
        if buffers:
            self._owner.run(lambda ctx: [b.release() for b in buffers.values()])

    def _run(self, call: Callable[[Any], T]) -> T:
        """Run a dispatch on the GL thread; after a failure, upload every mask again."""
        try:
            return self._owner.run(call)
        except BaseException:
            # _stage recorded the chunk's new masks as uploaded before the dispatch that
            # uploads them; forget them all so that the next chunk sends the whole table.
            self._masks = _Masks()
            raise

    def _per_request_bytes(self) -> int:
        height, width = self._field_shape
        return height * width * 4

    def _per_request_input_bytes(self) -> int:
        """Bytes per request of its largest input buffer: templates, previous passes or guides
        (or the 32-byte parameters of shaders/request.glsl, for a tiny block)."""
        return max(self._block * self._block * max(self._channels, self._guide_channels) * 4, 32)

    def _chunks(self, requests: Sequence[CostRequest]) -> list[Sequence[CostRequest]]:
        """Split a level so that every buffer and work-group count stays within the limits.

        The field (and the run minima, never larger) is held to :data:`MAX_FIELD_BYTES` as
        well as the device's storage-buffer limit; the inputs, one template (and previous
        pass, guide) per request, to the device's limit. :meth:`prepare` has checked that one
        request fits, so a chunk holds at least one.
        """
        if self._block == 0:
            raise RuntimeError("prepare() must be called before fields()")
        limits = self.info.limits
        ssbo = limits["max_ssbo_bytes"]
        per = min(
            min(ssbo, MAX_FIELD_BYTES) // self._per_request_bytes(),
            ssbo // self._per_request_input_bytes(),
            limits["max_groups"][2],
        )
        per = max(1, per)
        return [requests[k : k + per] for k in range(0, len(requests), per)]

    def _cost_group(self) -> tuple[int, int]:
        """The work-group shape of cost_field.comp: (LOCAL_X, LOCAL_Y), halved (y first)
        where the device allows fewer invocations or a smaller size per dimension."""
        limits = self.info.limits
        size_x, size_y = limits["max_group_size"][:2]
        invocations = limits["max_invocations"]
        x, y = LOCAL_X, LOCAL_Y
        while y > 1 and (y > size_y or x * y > invocations):
            y //= 2
        while x > 1 and (x > size_x or x * y > invocations):
            x //= 2
        return x, y

    def _reduce_group(self) -> int:
        """The work-group size of the selection kernels: :data:`LOCAL_REDUCE`, halved where
        the device allows fewer invocations (their loops stride by it, any size works)."""
        limits = self.info.limits
        size = LOCAL_REDUCE
        while size > 1 and (size > limits["max_group_size"][0] or size > limits["max_invocations"]):
            size //= 2
        return size

    def _relative_bound(self, request: CostRequest, mask_nonzero: int) -> tuple[float, float]:
        """``(rel, abs)``: |field - exact| <= rel * value / 2 + abs for this request.

        Every term is >= 0, so whatever order the driver sums in, the round-off is at most
        (terms - 1) eps times the sum; each term's own rounding (difference, dot product,
        weight) adds a few eps more. ``rel`` carries a factor 2 of safety; ``abs`` covers
        denormals flushed to zero.
        """
        terms = mask_nonzero * self._channels
        area = self._block * self._block
        if request.previous is not None and request.previous_weight > 0:
            terms += area * self._channels
        if request.guide is not None and request.guide_weight > 0:
            terms += area * self._guide_channels
        rel = 2.02 * (terms + 8) * _EPS32
        return rel, (terms + 8) * 2.0**-120

    def _run_shortlist(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        n = len(requests)
        field_size = self._field_shape[0] * self._field_shape[1]
        # Entries are 8 bytes: past the device's buffer limit the dense field is read instead.
        capacity = min(MAX_ENTRIES, n * field_size, self.info.limits["max_ssbo_bytes"] // 8)
        scale = 1.0 + tolerance
        staged = self._stage(requests)
        back = self._run(lambda ctx: self._dispatch(ctx, staged, (scale, min_candidates, capacity)))
        assert back.upper is not None
        if back.dense is not None:
            # The list overflowed: select from the dense field with the same bounds.
            fields = back.dense.reshape(n, *self._field_shape)
            top = fields.reshape(n, -1).max(axis=1)
            bounds = self._bounds(back.upper, staged, scale, top)
            return shortlist_fields(fields, bounds, tolerance, min_candidates)
        assert back.entries is not None
        entries = back.entries
        keys = entries[:, 0].astype(np.int64)
        values = entries[:, 1].view(np.float32).astype(np.float64)
        order = np.argsort(keys, kind="stable")
        keys, values = keys[order], values[order]
        owners, flat = np.divmod(keys, field_size)
        edges = np.searchsorted(owners, np.arange(n + 1))
        listed = [values[edges[k] : edges[k + 1]] for k in range(n)]
        tops = np.array([v.max() if v.size else 0.0 for v in listed])
        bounds = self._bounds(back.upper, staged, scale, tops)
        return [
            Shortlist(flat[edges[k] : edges[k + 1]].astype(np.intp), listed[k], float(bounds[k]))
            for k in range(n)
        ]

    @staticmethod
    def _bounds(
        upper: NDArray[np.float32], staged: _Staged, scale: float, top: NDArray[np.floating]
    ) -> NDArray[np.float64]:
        """Each request's error bound: from U where finite, else from its largest value ``top``
        (U is infinite only when the whole field is listed)."""
        u = upper.astype(np.float64)
        finite = np.isfinite(u)
        from_u = staged.rel * scale * np.where(finite, u, 0.0) + staged.absolute
        from_top = staged.rel * top.astype(np.float64) + staged.absolute
        return np.where(finite, from_u, from_top)

    def _stage(self, requests: Sequence[CostRequest]) -> _Staged:
        """Pack a chunk's inputs into arrays (host side, before the GL thread uploads them)."""
        n, block = len(requests), self._block
        new_masks = False
        params = np.zeros((n, 8), dtype=np.float32)
        rel = np.empty(n)
        absolute = np.empty(n)
        # One-off masks (a fill's) take slots after the job's shared ones for this chunk only:
        # kept, the table would grow and be uploaded again with every chunk.
        one_off: list[NDArray[np.float32]] = []
        for k, request in enumerate(requests):
            if not request.shared_mask:
                mask = np.ascontiguousarray(request.mask, dtype=np.float32)
                one_off.append(mask)
                slot = -len(one_off)  # made absolute below, once the shared table is known
                rel[k], absolute[k] = self._relative_bound(request, int(np.count_nonzero(mask)))
            else:
                found = find_mask(self._masks.arrays, request.mask)
                if found is None:
                    self._check_mask_table(len(self._masks.arrays) + 1)
                    mask = np.ascontiguousarray(request.mask, dtype=np.float32)
                    self._masks.arrays.append(mask)
                    self._masks.nonzero.append(int(np.count_nonzero(mask)))
                    found, new_masks = len(self._masks.arrays) - 1, True
                slot = found
                rel[k], absolute[k] = self._relative_bound(request, self._masks.nonzero[slot])
            params[k, 1] = request.previous_weight if request.previous is not None else 0.0
            params[k, 2] = request.guide_weight if request.guide is not None else 0.0
            params[k, 3], params[k, 4] = rel[k], absolute[k]
            params.view(np.int32)[k, 0] = slot
        if one_off:
            self._check_mask_table(len(self._masks.arrays) + len(one_off))
            slots = params.view(np.int32)[:, 0]
            slots[slots < 0] = len(self._masks.arrays) - 1 - slots[slots < 0]
        templates = np.stack([r.template for r in requests]).astype(np.float32, copy=False)
        has_previous = any(r.previous is not None and r.previous_weight > 0 for r in requests)
        has_guide = any(r.guide is not None and r.guide_weight > 0 for r in requests)
        zeros = np.zeros((block, block, self._channels), np.float32)
        previous = (
            np.stack([zeros if r.previous is None else r.previous for r in requests])
            if has_previous
            else None
        )
        guides = None
        if has_guide:
            if self._guide_channels == 0:
                raise ValueError("a request has a guide term but the source has no guide map")
            empty = np.zeros((block, block, self._guide_channels), np.float32)
            guides = np.stack([empty if r.guide is None else r.guide for r in requests])
        masks = spans = None
        if new_masks or one_off:
            masks = np.stack(self._masks.arrays + one_off)
            spans = np.zeros((masks.shape[0], block, 2), dtype=np.int32)
            nonzero_cols = masks != 0
            any_col = nonzero_cols.any(axis=2)
            spans[..., 0] = np.where(any_col, nonzero_cols.argmax(axis=2), 0)
            spans[..., 1] = np.where(any_col, block - nonzero_cols[:, :, ::-1].argmax(axis=2), 0)
        return _Staged(
            n=n,
            params=params,
            templates=np.ascontiguousarray(templates),
            previous=None if previous is None else np.ascontiguousarray(previous, np.float32),
            guides=None if guides is None else np.ascontiguousarray(guides, np.float32),
            masks=masks,
            spans=spans,
            rel=rel,
            absolute=absolute,
        )

    def _check_mask_table(self, count: int) -> None:
        """Refuse a table of ``count`` masks that would not fit in one storage buffer."""
        size = count * self._block * self._block * 4
        limit = self.info.limits["max_ssbo_bytes"]
        if size > limit:
            raise BackendError(
                f"the job's {count} distinct overlap masks ({self._block}x{self._block} float32, "
                f"{_mib(size)}) exceed this GPU's storage-buffer limit of {_mib(limit)}"
            )

    # -- GL thread -----------------------------------------------------------------------------

    def _upload(
        self, ctx: Any, source: NDArray[np.float32], guide: NDArray[np.float32] | None
    ) -> None:
        for buffer in self._buffers.values():
            buffer.release()
        self._buffers = {"source": ctx.buffer(source.tobytes())}
        if guide is not None:
            self._buffers["guide"] = ctx.buffer(guide.tobytes())
        _check(ctx, "the texture upload")

    def _buffer(self, ctx: Any, name: str, data: bytes | int) -> Any:
        """The job's buffer ``name``, grown when needed, filled with ``data`` (or sized)."""
        size = data if isinstance(data, int) else len(data)
        size = max(size, 16)
        buffer = self._buffers.get(name)
        if buffer is None or buffer.size < size:
            # Grow geometrically: a level's batch size changes from level to level.
            grown = size if buffer is None else max(size, buffer.size * 2)
            if buffer is not None:
                buffer.release()
            buffer = self._buffers[name] = ctx.buffer(reserve=grown)
        if not isinstance(data, int) and data:
            buffer.write(data)
        return buffer

    def _bound(self, name: str, ctx: Any = None, data: bytes | int | None = None) -> Any:
        """The job's buffer ``name`` bound at its slot (:data:`BINDINGS`); with ``data``,
        first grown and filled by :meth:`_buffer`."""
        buffer = self._buffers[name] if data is None else self._buffer(ctx, name, data)
        buffer.bind_to_storage_buffer(BINDINGS[name])
        return buffer

    def _program(self, ctx: Any, name: str, defines: dict[str, int]) -> Any:
        key = (name, tuple(sorted(defines.items())))
        program = self._owner.programs.get(key)
        if program is None:
            try:
                program = ctx.compute_shader(shader_source(name, defines))
            except moderngl.Error as exc:
                raise BackendError(f"the shader {name} did not compile: {exc}") from exc
            self._owner.programs[key] = program
        return program

    def _dispatch(
        self, ctx: Any, staged: _Staged, select: tuple[float, int, int] | None
    ) -> _Readback:
        """Run the kernels for one chunk; with ``select`` = (scale, k, capacity) read back the
        shortlist (or, on overflow, the dense field), without it the dense field."""
        try:
            return self._dispatch_unchecked(ctx, staged, select)
        except moderngl.Error as exc:
            raise BackendError(f"OpenGL failed: {exc}") from exc

    def _dispatch_unchecked(
        self, ctx: Any, staged: _Staged, select: tuple[float, int, int] | None
    ) -> _Readback:
        n = staged.n
        width = self._source_shape[1]
        fh, fw = self._field_shape
        groups_w = -(-fw // RUN)
        limits = self.info.limits
        local_x, local_y = self._cost_group()
        dims = (-(-groups_w // local_x), -(-fh // local_y), n)
        if any(d > m for d, m in zip(dims, limits["max_groups"], strict=True)):
            raise BackendError(
                f"a dispatch of {dims} work groups exceeds this GPU's limit {limits['max_groups']}"
            )
        defines = {
            "BLOCK": self._block,
            "CHANNELS": self._channels,
            "GUIDE_CHANNELS": self._guide_channels if staged.guides is not None else 0,
            "HAS_PREVIOUS": int(staged.previous is not None),
            "RUN": RUN,
            "LOCAL_X": local_x,
            "LOCAL_Y": local_y,
        }
        cost = self._program(ctx, "cost_field.comp", defines)
        if staged.masks is not None and staged.spans is not None:  # the table grew: upload it
            self._buffer(ctx, "masks", staged.masks.tobytes())
            self._buffer(ctx, "spans", staged.spans.tobytes())
        self._bound("source")
        self._bound("masks")
        self._bound("spans")
        self._bound("templates", ctx, staged.templates.tobytes())
        self._bound("requests", ctx, staged.params.tobytes())
        if staged.previous is not None:
            self._bound("previous", ctx, staged.previous.tobytes())
        if staged.guides is not None:
            self._bound("guide")
            self._bound("guides", ctx, staged.guides.tobytes())
        field_bytes = n * fh * fw * 4
        fields = self._bound("field", ctx, field_bytes)
        self._bound("minima", ctx, n * fh * groups_w * 4)
        _check(ctx, "the upload of the level's inputs")
        cost["src_w"] = width
        cost["field_w"] = fw
        cost["field_h"] = fh
        cost["groups_w"] = groups_w
        cost.run(*dims)
        _check(ctx, "the cost_field.comp dispatch")
        ctx.memory_barrier()
        if select is None:
            values = np.frombuffer(fields.read(field_bytes), dtype=np.float32).copy()
            _check(ctx, "the readback of the cost fields")
            return _Readback(dense=values)

        scale, k, capacity = select
        header = self._kth_bound(ctx, n, fh * groups_w, k)
        entries = self._bound("entries", ctx, capacity * 8)
        local = self._reduce_group()
        compact = self._program(ctx, "shortlist.comp", {"LOCAL_X": local})
        field_size = fh * fw
        groups = -(-field_size // local)
        gx = min(groups, limits["max_groups"][0])
        gy = -(-groups // gx)
        if gy > limits["max_groups"][1]:
            raise BackendError(f"a field of {field_size} candidates exceeds the work-group limits")
        compact["field_size"] = field_size
        compact["capacity"] = capacity
        compact["scale"] = scale
        compact.run(gx, gy, n)
        _check(ctx, "the shortlist.comp dispatch")
        ctx.memory_barrier()
        raw = header.read(16 + 4 * n)
        total = int(np.frombuffer(raw, dtype=np.uint32, count=1)[0])
        upper = np.frombuffer(raw, dtype=np.float32, offset=16).copy()
        if total > capacity:
            values = np.frombuffer(fields.read(field_bytes), dtype=np.float32).copy()
            _check(ctx, "the readback of the cost fields")
            return _Readback(upper=upper, dense=values)
        listed = np.frombuffer(entries.read(total * 8), dtype=np.uint32).reshape(total, 2)
        _check(ctx, "the readback of the shortlist")
        return _Readback(upper=upper, entries=listed.copy())

    def _kth_bound(self, ctx: Any, n: int, count: int, k: int) -> Any:
        """Run kth_bound.comp over the ``n x count`` run minima already in the ``minima``
        buffer; return the ``header`` buffer, its ``total`` zeroed and U per request after it."""
        local = self._reduce_group()
        shared = self.info.limits["max_shared_bytes"]
        if shared < KTH_SHARED_BYTES:
            raise BackendError(
                f"kth_bound.comp needs {KTH_SHARED_BYTES} bytes of shared memory; this GPU "
                f"gives a work group {shared}"
            )
        header = self._bound("header", ctx, bytes(16 + 4 * n))
        kth = self._program(ctx, "kth_bound.comp", {"LOCAL_X": local})
        kth["count"] = count
        kth["k"] = k
        self._bound("minima")
        kth.run(n, 1, 1)
        _check(ctx, "the kth_bound.comp dispatch")
        ctx.memory_barrier()
        return header


@dataclass(frozen=True)
class _Staged:
    """One chunk's inputs, packed for upload."""

    n: int
    params: NDArray[np.float32]  # (n, 8): mask slot (int bits), w_prev, w_guide, rel, abs
    templates: NDArray[np.float32]  # (n, B, B, C)
    previous: NDArray[np.float32] | None  # (n, B, B, C)
    guides: NDArray[np.float32] | None  # (n, B, B, K)
    masks: NDArray[np.float32] | None  # (m, B, B): every mask so far, when one is new
    spans: NDArray[np.int32] | None  # (m, B, 2): columns [c0, c1) of each mask row
    rel: NDArray[np.float64]  # (n,)
    absolute: NDArray[np.float64]  # (n,)


@dataclass(frozen=True)
class _Readback:
    """What one chunk's dispatch read back from the GPU."""

    upper: NDArray[np.float32] | None = None  # (n,): U per request (shortlist dispatches)
    entries: NDArray[np.uint32] | None = None  # (m, 2): (request * field size + index, bits)
    dense: NDArray[np.float32] | None = None  # (n * fh * fw,): the fields, when read whole
