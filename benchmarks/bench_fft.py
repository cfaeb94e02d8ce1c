"""The FFT backend's transforms with each FFT library at hand: which one to use (issue 21).

Per block of a level, the ``fft`` backend (:mod:`quilting.costs.fft`) transforms its masked
template (B x B x C) onto the source's FFT grid (Nh x Nw) and the correlation back: a real
transform along the rows of the B non-zero rows, a complex one along the columns, the spectral
product over the channels, a complex inverse along the columns and a real one along the rows
of the field's H - B + 1 rows. This script times that sequence, the transforms alone, for a
level of 17 blocks of 48 (RGB, as at 2048² from a 256² texture) against 256² and 512²
sources, with:

* ``scipy``: ``scipy.fft`` (pocketfft, BSD), what the backend uses;
* ``ducc0``: ``ducc0.fft`` (pocketfft's successor, GPL-2.0-or-later), if installed;
* ``pyfftw``: ``pyfftw.interfaces.scipy_fft`` (FFTW, GPL-2.0-or-later), planned once
  (``FFTW_MEASURE``, the wisdom kept), if installed.

Each library runs single-threaded (the backend spreads the blocks of a level over its own
threads) and takes turns with the others, round after round; the table gives each one's median
over the rounds of its microseconds per block and its speed relative to scipy. It also checks
that each library's result is scipy's to float32 round-off.

Run from the repository root (the optional libraries installed by hand, they are not
dependencies of the project)::

    .venv/bin/pip install ducc0 pyfftw     # optional, for the comparison only
    .venv/bin/python benchmarks/bench_fft.py
    .venv/bin/python benchmarks/bench_fft.py --rounds 7 --sources 256
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import time
from collections.abc import Callable

import benchtools
import numpy as np
import scipy
import scipy.fft as sfft
from numpy.typing import NDArray

BLOCK = 48
BLOCKS = 17
CHANNELS = 3

Transforms = Callable[[NDArray[np.float32], NDArray[np.complex64]], NDArray[np.float32]]


def sequence(
    rfft: Callable[..., NDArray[np.complex64]],
    fft: Callable[..., NDArray[np.complex64]],
    ifft: Callable[..., NDArray[np.complex64]],
    irfft: Callable[..., NDArray[np.float32]],
    shape: tuple[int, int],
) -> Transforms:
    """The backend's sequence with one library's four 1-D transforms (scipy's signatures)."""
    nh, nw = shape
    rows = nh - BLOCK + 1

    def run(kernels: NDArray[np.float32], source: NDArray[np.complex64]) -> NDArray[np.float32]:
        spectra = fft(rfft(kernels, n=nw, axis=-1), n=nh, axis=-2)
        product = np.conj((spectra * source[None]).sum(axis=1))
        columns = ifft(product, axis=-2)[:, :rows]
        return irfft(columns, n=nw, axis=-1)

    return run


def libraries(shape: tuple[int, int]) -> dict[str, Transforms]:
    """Every library found, as the backend's sequence."""
    found: dict[str, Transforms] = {
        "scipy": sequence(sfft.rfft, sfft.fft, sfft.ifft, sfft.irfft, shape)
    }
    if importlib.util.find_spec("ducc0") is not None:
        import ducc0

        nh, nw = shape

        def d_rfft(x: NDArray[np.float32], n: int, axis: int) -> NDArray[np.complex64]:
            padded = np.zeros((*x.shape[:-1], n), dtype=np.float32)
            padded[..., : x.shape[-1]] = x
            out: NDArray[np.complex64] = ducc0.fft.r2c(padded, axes=(padded.ndim - 1,))
            return out

        def d_fft(x: NDArray[np.complex64], n: int, axis: int) -> NDArray[np.complex64]:
            padded = np.zeros((*x.shape[:-2], n, x.shape[-1]), dtype=np.complex64)
            padded[..., : x.shape[-2], :] = x
            out: NDArray[np.complex64] = ducc0.fft.c2c(padded, axes=(padded.ndim - 2,), out=padded)
            return out

        def d_ifft(x: NDArray[np.complex64], axis: int) -> NDArray[np.complex64]:
            out: NDArray[np.complex64] = ducc0.fft.c2c(
                x, axes=(x.ndim - 2,), forward=False, inorm=2
            )
            return out

        def d_irfft(x: NDArray[np.complex64], n: int, axis: int) -> NDArray[np.float32]:
            out: NDArray[np.float32] = ducc0.fft.c2r(
                np.ascontiguousarray(x), axes=(x.ndim - 1,), lastsize=n, forward=False, inorm=2
            )
            return out

        found["ducc0"] = sequence(d_rfft, d_fft, d_ifft, d_irfft, (nh, nw))
    if importlib.util.find_spec("pyfftw") is not None:
        import pyfftw
        import pyfftw.interfaces.scipy_fft as wfft

        pyfftw.interfaces.cache.enable()
        pyfftw.config.PLANNER_EFFORT = "FFTW_MEASURE"
        pyfftw.config.NUM_THREADS = 1
        found["pyfftw"] = sequence(wfft.rfft, wfft.fft, wfft.ifft, wfft.irfft, shape)
    return found


def per_block(
    run: Transforms, kernels: NDArray[np.float32], source: NDArray[np.complex64]
) -> float:
    """Microseconds a block of one call of ``run`` over the level, best of a few calls."""
    best = float("inf")
    deadline = time.perf_counter() + 0.4
    while time.perf_counter() < deadline:
        tick = time.perf_counter()
        run(kernels, source)
        best = min(best, time.perf_counter() - tick)
    return float(best / kernels.shape[0] * 1e6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--sources", default="256,512", help="source sides, comma-separated")
    args = parser.parse_args()
    print("machine:", benchtools.machine(numpy=np.__version__, scipy=scipy.__version__))
    rng = np.random.default_rng(0)
    mask = np.zeros((BLOCK, BLOCK), dtype=np.float32)
    mask[:, :8] = mask[:8, :] = 1
    kernels = (rng.random((BLOCKS, CHANNELS, BLOCK, BLOCK)) * mask).astype(np.float32)
    rows = []
    for side in (int(s) for s in args.sources.split(",")):
        shape = (sfft.next_fast_len(side), sfft.next_fast_len(side, real=True))
        planes = rng.random((CHANNELS, side, side)).astype(np.float32)
        source = np.conj(sfft.rfft2(planes, s=shape)).astype(np.complex64)
        found = libraries(shape)
        want = found["scipy"](kernels, source)
        scale = float(np.abs(want).max())
        for name, run in found.items():
            error = float(np.abs(run(kernels, source) - want).max()) / scale
            if error > 1e-5:
                raise SystemExit(f"{name}: result off scipy's by {error:.2e} of its largest value")
        times: dict[str, list[float]] = {name: [] for name in found}
        for _ in range(args.rounds):
            for name, run in found.items():
                times[name].append(per_block(run, kernels, source))
        base = statistics.median(times["scipy"])
        for name, spent in times.items():
            median = statistics.median(spent)
            rows.append([f"{side}²", name, f"{median:.0f}", f"{base / median:.2f}"])
        print(f"  {side}² done", flush=True)
    print()
    print(benchtools.markdown(["source", "library", "us a block", "x scipy"], rows, left=2))
    print("\nload average at the end:", [round(x, 2) for x in os.getloadavg()])


if __name__ == "__main__":
    main()
