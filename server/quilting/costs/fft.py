"""The CPU backend: cost fields by FFT correlation.

``E = sum M*S^2 - 2 sum (M*T) * S + sum M*T^2`` at every candidate position. The first term
depends only on the mask and is computed once per mask shape and job (float64); the last is one
number per request; the cross term is a correlation of the masked template with the source,
done with float32 FFTs against source spectra computed once per job. Only the templates are
transformed per block, and only their non-zero B x B corner is fed to the first 1-D pass.

Float32 round-off makes the field approximate: each field comes with a bound on its error
(derived from the norms of template and source) and the engine re-scores exactly the
candidates that fall within that bound of a decision threshold.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from quilting.core.fields import CostRequest, FieldBatch

#: Unit round-off of float32.
_EPS32 = float(np.finfo(np.float32).eps) / 2
#: Safety factor over the usual FFT error estimate eps * log2(N) * |K| * |S|. Measured errors
#: (random inputs and the test textures, every mask) stay below 1/15 of the resulting bound;
#: a looser bound only costs time, as more candidates are re-scored exactly.
_SAFETY = 2.0
#: Most requests transformed together.
_CHUNK = 6


class FFTBackend:
    """Cost fields by FFT correlation with cached source spectra.

    Parameters
    ----------
    threads : int, optional
        Requests of one batch are split across this many threads (numpy and pocketfft release
        the GIL). Default: ``min(2, cores)``. Results do not depend on it.
    """

    name = "fft"

    def __init__(self, threads: int | None = None) -> None:
        self.threads = max(1, threads if threads is not None else min(2, os.cpu_count() or 1))
        self._pool: ThreadPoolExecutor | None = None
        self._block = 0
        self._fft_shape = (0, 0)
        self._field_shape = (0, 0)
        self._spectrum: NDArray[np.complex64] | None = None  # (C, Nh, Nw // 2 + 1)
        self._spectrum_conj: NDArray[np.complex64] = np.empty((0, 0, 0), dtype=np.complex64)
        self._energy_spectrum: NDArray[np.complex128] | None = None  # of sum_c S_c^2
        self._energy: dict[bytes, tuple[NDArray[np.float32], float, float]] = {}
        self._lock = threading.Lock()
        self._source_norm = 0.0

    def prepare(self, source: NDArray[np.float32], block: int) -> None:
        height, width, _ = source.shape
        # Circular correlation on an FFT grid at least the source's size is exact at every
        # valid position: y + u never passes the last source row.
        nh, nw = sfft.next_fast_len(height), sfft.next_fast_len(width, real=True)
        planes = np.ascontiguousarray(source.transpose(2, 0, 1), dtype=np.float32)
        self._block = block
        self._fft_shape = (nh, nw)
        self._field_shape = (height - block + 1, width - block + 1)
        self._spectrum = sfft.rfft2(planes, s=(nh, nw))
        self._spectrum_conj = np.conj(self._spectrum)
        squares = (planes.astype(np.float64) ** 2).sum(axis=0)
        self._energy_spectrum = sfft.rfft2(squares, s=(nh, nw))
        self._energy = {}
        self._source_norm = float(np.sqrt(squares.sum()))
        if self.threads > 1 and self._pool is None:
            self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="quilting-fft")

    def _mask_energy(self, mask: NDArray[np.float32]) -> tuple[NDArray[np.float32], float, float]:
        """``sum M * S^2`` at every candidate position (cached per mask), its error, its max."""
        key = mask.tobytes()
        cached = self._energy.get(key)
        if cached is not None:
            return cached
        with self._lock:  # worker threads may ask for the same new mask at once
            cached = self._energy.get(key)
            if cached is None:
                assert self._energy_spectrum is not None
                kernel = sfft.rfft2(mask.astype(np.float64), s=self._fft_shape)
                full = sfft.irfft2(np.conj(kernel) * self._energy_spectrum, s=self._fft_shape)
                exact = full[: self._field_shape[0], : self._field_shape[1]]
                # float32 storage rounds by half an ulp; the float64 FFT adds ~1e-16 relative.
                top = float(np.abs(exact).max())
                cached = (exact.astype(np.float32), top * (_EPS32 + 1e-12), top)
                self._energy[key] = cached  # one assignment: readers see both or neither
        return cached

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        if self._spectrum is None:
            raise RuntimeError("prepare() must be called before fields()")
        # Chunks of a few requests keep each chunk's spectra in cache (measured: 4-8 per chunk
        # is ~15 % faster than 16 or more) and give the threads work to share.
        share = min(_CHUNK, -(-len(requests) // self.threads))
        parts = [requests[i : i + share] for i in range(0, len(requests), share)]
        if self._pool is None or len(parts) == 1:
            done = [self._fields(part) for part in parts]
        else:
            done = list(self._pool.map(self._fields, parts))
        if len(done) == 1:
            return done[0]
        return FieldBatch(
            np.concatenate([d.values for d in done]), np.concatenate([d.error_bound for d in done])
        )

    def _fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        assert self._spectrum is not None
        nh, nw = self._fft_shape
        fh, fw = self._field_shape
        masks = np.stack([r.mask for r in requests])  # (n, B, B)
        templates = np.stack([r.template for r in requests])  # (n, B, B, C)
        kernels = np.ascontiguousarray((templates * masks[..., None]).transpose(0, 3, 1, 2))
        # 2-D transform of a B x B kernel on the Nh x Nw grid: rows first on the B non-zero
        # rows only, then columns.
        spectra = sfft.fft(sfft.rfft(kernels, n=nw, axis=-1), n=nh, axis=-2, overwrite_x=True)
        # sum_c conj(K_c) S_c = conj(sum_c K_c conj(S_c)): one conjugation of the sum instead
        # of one per channel.
        product = spectra[:, 0]
        product *= self._spectrum_conj[0]
        for channel in range(1, spectra.shape[1]):
            spectra[:, channel] *= self._spectrum_conj[channel]
            product += spectra[:, channel]
        np.conjugate(product, out=product)
        columns = sfft.ifft(product, axis=-2, overwrite_x=True)[:, :fh]
        values = sfft.irfft(columns, n=nw, axis=-1)[:, :, :fw]  # the cross term, float32

        template_energy = np.einsum(
            "nyxc,nyx->n", templates.astype(np.float64) ** 2, masks.astype(np.float64)
        )
        kernel_norms = np.sqrt(np.einsum("ncyx,ncyx->n", kernels, kernels, dtype=np.float64))
        gamma = _SAFETY * _EPS32 * math.log2(nh * nw)
        bounds = np.empty(len(requests), dtype=np.float64)
        values *= -2
        for k, request in enumerate(requests):
            energy, energy_error, energy_max = self._mask_energy(request.mask)
            values[k] += energy
            values[k] += np.float32(template_energy[k])
            top = energy_max + template_energy[k]
            # The float32 cross term dominates; the sums above each round by half an ulp of
            # at most `top`.
            bounds[k] = (
                2 * gamma * kernel_norms[k] * self._source_norm + energy_error + 3 * _EPS32 * top
            )
        return FieldBatch(values, bounds)

    def close(self) -> None:
        self._spectrum = None
        self._energy_spectrum = None
        self._energy = {}
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None
