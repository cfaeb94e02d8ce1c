"""Inside a sandbox process: the pixel work it does for the API, and its end of the pipe.

The pool in the API process (:class:`quilting.service.sandbox.Sandbox`) spawns processes that
run :func:`sandbox_main`; this module is what they import, and all that they do:

- ``check``: a submission's uploads decoded and checked against each other and the options
  (:func:`quilting.service.uploads.check`); only the output size goes back;
- ``tile``: ``POST /tile`` (:func:`tile_png`); PNG bytes back;
- ``seams``: the seam overlay of ``GET /jobs/{id}/seams`` (:func:`seams_png`); PNG bytes back.

The protocol, one call at a time: the pool sends ``("call", task, args)``; the process
acknowledges ``("started",)`` (a death after that is the call's), then answers ``("ok",
value)``, ``("problem", status, code, detail, headers, extra)``, ``("error", traceback)`` for a
bug, or ``("memory",)``, after which it exits. ``None`` asks it to stop.
"""

from __future__ import annotations

import contextlib
import os
import signal
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from quilting import (
    FillLayout,
    Layout,
    QuiltingError,
    __version__,
    is_fill_layout,
    seam_mask,
    warm_up,
)
from quilting.api import make_tileable
from quilting.io import encode_png
from quilting.options import TileOptions
from quilting.service import uploads
from quilting.service.jobs import PixelLimits
from quilting.service.memory_limit import limit_memory
from quilting.service.problems import Problem, from_engine
from quilting.service.upload_images import read_upload

#: How much lower a sandbox process's CPU priority is than the API process's.
NICENESS = 10


def tile_png(data: bytes, options: TileOptions, limits: PixelLimits) -> bytes:
    """``POST /tile``: decode (the output has the image's size: the tighter pixel limit
    applies), make tileable (by cutting, or by filling the bands across the wraps: the
    options' ``method``), encode with the image's bit depth."""
    decoded = read_upload(data, "image", *limits.output_sized())
    try:
        tiled = make_tileable(decoded, options)
    except QuiltingError as exc:
        raise from_engine(exc) from None
    del decoded
    meta = {"operation": "tile", **options.to_dict(), "version": __version__}
    return encode_png(tiled.image, metadata=meta)


def seams_png(layout_json: bytes, color: str) -> bytes:
    """RGBA, of the result's size: ``color`` (RRGGBB) on the seams, transparent elsewhere."""
    mask = (
        FillLayout.from_json(layout_json).seam_mask()
        if is_fill_layout(layout_json)
        else seam_mask(Layout.from_json(layout_json))
    )
    rgba = np.zeros((*mask.shape, 4), dtype=np.uint8)
    rgba[mask] = (*bytes.fromhex(color), 255)
    return encode_png(rgba)


#: The calls a sandbox process takes, by name (a name, not a pickled function, crosses over).
TASKS: dict[str, Callable[..., Any]] = {
    "check": uploads.check,
    "tile": tile_png,
    "seams": seams_png,
}


def sandbox_main(conn: Connection, budget: int) -> None:
    """Body of a sandbox process: limit itself, then answer calls until told to stop.

    Parameters
    ----------
    conn : Connection
        Its end of the pipe to the pool (the protocol is in the module's docstring).
    budget : int
        Bytes a call may allocate beyond what the process holds once started
        (``job_memory_bytes``).
    """
    # Ctrl-C in a terminal reaches the whole process group; the service stops its sandbox.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # Below the API process, which only waits for this one: the event loop is scheduled
    # first, and /healthz stays quick while an upload is decoded here. A niceness, not
    # SCHED_IDLE: an idle-class process gets no CPU at all while the job workers keep every
    # core busy, and then an ordinary upload's check outlasts sandbox_timeout_s (seen in CI).
    # (The 100-190 ms /healthz that SCHED_IDLE was meant to remove were the benchmark's own
    # garbage collections; with the probe in a process of its own, niceness 10 gives 37-43 ms.)
    with contextlib.suppress(OSError):
        os.nice(NICENESS)
    # make_tileable's cuts run compiled: loaded before the cap, like a worker's.
    warm_up()
    cap = limit_memory(budget)
    conn.send(("ready", cap))
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return  # the service is gone
        if message is None:
            return
        conn.send(("started",))
        try:
            # Unpacked in here: a message of another shape is answered as a bug, not the end
            # of the process.
            _, task, args = message
            answer: tuple[Any, ...] = ("ok", TASKS[task](*args))
        except Problem as problem:
            answer = (
                "problem",
                problem.status,
                problem.code,
                problem.detail,
                problem.headers,
                problem.extra,
            )
        except MemoryError:
            answer = ("memory",)
        except Exception:
            answer = ("error", traceback.format_exc())
        try:
            conn.send(answer)
        except MemoryError:  # the answer itself did not fit
            answer = ("memory",)
            conn.send(answer)
        if answer[0] == "memory":
            return
