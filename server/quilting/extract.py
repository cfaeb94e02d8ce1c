"""Alpha from an ordinary photo: the one module that imports the matting library (pymatting,
the optional extra ``quilting[matting]``).

A photo of ice, smoke or leaves has no alpha channel; the user says which parts are surely
foreground and background (a trimap or scribbles, :mod:`quilting.core.trimap`), a matting
solver finds the alpha in between, and the foreground colour is estimated so that the colour
of the background showing through semi-transparent pixels does not stay in the texture.

Why pymatting: it implements the seed's method (closed-form matting) beside KNN and
large-kernel matting, and foreground estimation, on numpy, scipy and numba, which the engine
already depends on (nothing compiled to install); MIT licence; maintained (1.1.x). Its solvers
are conjugate gradients whose iterations this module bounds and watches (progress, cancel).

References
----------
.. [1] A. Levin, D. Lischinski and Y. Weiss, "A Closed-Form Solution to Natural Image
       Matting", IEEE TPAMI 30(2), 2008, §3 (the matting Laplacian, ``method='cf'``).
.. [2] Q. Chen, D. Li and C.-K. Tang, "KNN Matting", IEEE TPAMI 35(9), 2013, §3
       (``method='knn'``).
.. [3] K. He, J. Sun and X. Tang, "Fast Matting Using Large Kernel Matting Laplacian
       Matrices", CVPR 2010, §3 (``method='lkm'``).
.. [4] T. Germer, T. Uelwer, S. Conrad and S. Harmeling, "Fast Multi-Level Foreground
       Estimation", ICPR 2020, §3 (``foreground='ml'``).
.. [5] The alpha quilting and texture matting paper, §2: the foreground texture and its matte
       are obtained from the sample photo and the user's scribbles or trimap this way.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quilting._keywords import option_keywords
from quilting.core.budget import Budget, estimate_extract
from quilting.core.errors import QuiltingError
from quilting.core.options import AlphaOptions
from quilting.core.pixels import PixelFormat
from quilting.core.progress import Progress
from quilting.core.trimap import UNKNOWN, Extracted, photo_pixels, rgba, user_trimap

__all__ = [
    "Extracted",
    "MattingUnavailableError",
    "available",
    "check_extract",
    "extract_alpha",
    "load",
]

#: Most conjugate-gradient iterations of one solve (what bounds its time); the methods converge
#: in 30-300 (knn, lkm) and 3-2500 (cf) on the benchmark's photos.
MAX_ITERATIONS = 5000
#: The solvers' stopping rule: the residual's norm under this share of the right-hand side's.
RTOL = 1e-7
#: Non-zeros the closed-form solver's incomplete Cholesky preconditioner may hold, per
#: unknown pixel (16 bytes each): past it the plain diagonal is used instead, so that its
#: memory is bounded by the photo, not by how its factor fills in.
ICHOL_FILL = 40
#: Large-kernel matting's window radius (pymatting's default), smaller on a small photo.
LKM_RADIUS = 10


#: What a missing matting extra is told as.
UNAVAILABLE = "extracting alpha needs the matting extra: pip install 'quilting[matting]'"


class MattingUnavailableError(QuiltingError):
    """The optional matting library is not installed."""

    code = "matting_unavailable"


def available() -> bool:
    """Whether the matting extra (pymatting) is installed; found without importing it (its
    first import compiles its solvers: about 20 s once per installation, :func:`load`)."""
    return importlib.util.find_spec("pymatting") is not None


def load() -> None:
    """Import the matting library now, when it is installed (the service's workers do at
    start, so that no job pays its compile)."""
    if available():
        _library()


def _library() -> Any:
    try:
        import pymatting
    except ImportError as exc:  # pragma: no cover - the CI installs the extra
        raise MattingUnavailableError(UNAVAILABLE) from exc
    return pymatting


def _preconditioner(pm: Any, method: str) -> Callable[[Any], Any] | None:
    """cf: incomplete Cholesky while it stays small and exists, else the diagonal."""
    if method != "cf":
        return None

    def bounded(matrix: Any) -> Any:
        # pymatting prints its retries with larger shifts; they are not the user's business.
        with contextlib.redirect_stdout(io.StringIO()):
            try:
                return pm.ichol(
                    matrix,
                    max_nnz=ICHOL_FILL * matrix.shape[0] + 1,
                    shifts=[0.0, 1e-3, 1e-1],
                )
            except ValueError:
                return pm.jacobi(matrix)

    return bounded


def _solve(
    pm: Any,
    pixels: NDArray[np.float64],
    marked: NDArray[np.float64],
    method: str,
    progress: Progress | None,
) -> tuple[NDArray[np.float64], int]:
    """The alpha (h, w) and the iterations the solver took."""
    done = [0]
    # log of the residual's target: the solve is done when log(|r| / |b|) reaches it.
    goal = math.log(RTOL)

    def watch(_a: Any, _x: Any, _b: Any, norm_b: float, _r: Any, norm_r: float) -> None:
        done[0] += 1
        if progress is not None and done[0] % 10 == 0:
            ratio = norm_r / norm_b if norm_b > 0 else RTOL
            fraction = min(1.0, max(0.0, math.log(max(ratio, RTOL)) / goal))
            progress(0.9 * fraction, "alpha")

    cg = {"maxiter": MAX_ITERATIONS, "rtol": RTOL, "callback": watch}
    solvers = {
        "cf": pm.estimate_alpha_cf,
        "knn": pm.estimate_alpha_knn,
        "lkm": pm.estimate_alpha_lkm,
    }
    keywords: dict[str, Any] = {"cg_kwargs": cg}
    if method == "lkm":
        # Its box filters need the window's side (2 radius + 1) to fit twice in the photo.
        side = min(pixels.shape[0], pixels.shape[1])
        keywords["laplacian_kwargs"] = {"radius": max(1, min(LKM_RADIUS, (side - 1) // 4))}
    preconditioner = _preconditioner(pm, method)
    if preconditioner is not None:
        keywords["preconditioner"] = preconditioner
    alpha = solvers[method](pixels, marked, **keywords)
    # The solvers clip to [0, 1]; the known pixels are set exactly, as the user drew them.
    alpha = np.where(marked == UNKNOWN, alpha, marked)
    return alpha, done[0]


def _inputs(
    photo: object, trimap: object | None, scribbles: object | None
) -> tuple[NDArray[np.float64], PixelFormat, NDArray[np.float64]]:
    """The photo as the solvers take it, its format, and the map its trimap and scribbles
    make (see :func:`check_extract` for what is refused)."""
    pixels, fmt = photo_pixels(photo)
    return pixels, fmt, user_trimap((pixels.shape[0], pixels.shape[1]), trimap, scribbles)


def check_extract(
    photo: object, trimap: object | None = None, scribbles: object | None = None
) -> None:
    """Refuse what :func:`extract_alpha` would refuse of a photo and its maps, without
    solving (milliseconds): the service checks a submission with it before queueing it.

    Raises
    ------
    InvalidTrimapError
        No trimap or scribbles, one of another size than the photo, or marking no foreground
        or no background.
    InvalidImageError
        A photo that already has alpha, that is too small, or that is no image.
    MattingUnavailableError
        The ``matting`` extra is not installed.
    """
    _inputs(photo, trimap, scribbles)
    if not available():
        raise MattingUnavailableError(UNAVAILABLE)


@option_keywords(AlphaOptions)
def extract_alpha(
    photo: object,
    trimap: object | None = None,
    scribbles: object | None = None,
    options: AlphaOptions | None = None,
    *,
    progress: Progress | None = None,
    budget: Budget | None = None,
    **overrides: Any,
) -> Extracted:
    """An RGBA texture from an ordinary photo and a trimap or scribbles.

    Parameters
    ----------
    photo : ndarray, shape (h, w) or (h, w, C)
        C in 1 or 3 (a photo with alpha already has what this makes); uint8, uint16 or float.
    trimap : ndarray, shape (h, w) or (h, w, C), optional
        White where the photo is surely foreground, black where surely background, grey where
        the alpha is to be found (:func:`quilting.core.trimap.user_trimap` says how exactly).
    scribbles : ndarray, shape (h, w) or (h, w, C), optional
        White and black strokes, the rest unknown (transparent or grey). With a trimap, drawn
        over it. One of the two is needed; together they must mark some foreground and some
        background.
    options : AlphaOptions, optional
        The matting ``method`` and how the ``foreground`` colour is found (default:
        ``AlphaOptions()``); any of its fields given as a keyword replaces the one in it.
    progress : callable, optional
        ``progress(fraction, stage)`` (stage ``"alpha"``, then ``"foreground"``) during the
        solve; raise from it to stop.
    budget : Budget, optional
        Memory and time the extraction may take, checked before any work against
        :func:`quilting.core.budget.estimate_extract` (which counts every pixel as unknown).

    {option_keywords}

    Returns
    -------
    Extracted
        ``image`` (h, w, 4) in the photo's dtype, ``alpha``, ``trimap``, the method, the
        solver's iterations and the timings.

    Raises
    ------
    InvalidTrimapError
        No trimap or scribbles, one of another size than the photo, or marking no foreground
        or no background (code ``invalid_trimap``).
    InvalidImageError
        A photo that already has alpha, or that is no image.
    MattingUnavailableError
        The ``matting`` extra is not installed.

    References
    ----------
    .. [1] The alpha quilting and texture matting paper, §2.
    .. [2] A. Levin, D. Lischinski and Y. Weiss, "A Closed-Form Solution to Natural Image
           Matting", IEEE TPAMI 30(2), 2008, §3.
    """
    options = AlphaOptions.resolve(options, overrides, caller="extract_alpha")
    pixels, fmt, marked = _inputs(photo, trimap, scribbles)
    estimate_extract(options, (pixels.shape[0], pixels.shape[1]), budget=budget)
    pm = _library()
    start = time.perf_counter()
    alpha, iterations = _solve(pm, pixels, marked, options.method, progress)
    solved = time.perf_counter()
    if progress is not None:
        progress(0.9, "foreground")
    colour = pm.estimate_foreground_ml(pixels, alpha) if options.foreground == "ml" else pixels
    finished = time.perf_counter()
    if progress is not None:
        progress(1.0, "foreground")
    return Extracted(
        image=rgba(colour, alpha, fmt),
        alpha=alpha.astype(np.float32),
        trimap=marked.astype(np.float32),
        method=options.method,
        foreground=options.foreground,
        iterations=iterations,
        timings={
            "alpha": solved - start,
            "foreground": finished - solved,
            "total": finished - start,
        },
    )
