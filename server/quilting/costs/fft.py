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
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from quilting.core.fields import CostRequest, FieldBatch
from quilting.core.select import DenseShortlists

#: Unit round-off of float32.
_EPS32 = float(np.finfo(np.float32).eps) / 2
#: Safety factor over the usual FFT error estimate eps * log2(N) * |K| * |S|. Measured errors
#: (random inputs and the test textures, every mask) stay below 1/15 of the resulting bound;
#: a looser bound only costs time, as more candidates are re-scored exactly.
_SAFETY = 2.0
#: Most requests transformed together.
_CHUNK = 6


@dataclass(frozen=True)
class _Map:
    """What the backend keeps of an image it correlates with (the source or its guide map)."""

    spectrum_conj: NDArray[np.complex64]  # (C, Nh, Nw // 2 + 1), conjugated
    energy_spectrum: NDArray[np.complex128]  # of sum_c X_c^2, float64
    norm: float  # Frobenius norm of X, for the error bound


class FFTBackend(DenseShortlists):
    """Cost fields by FFT correlation with cached source spectra.

    Parameters
    ----------
    threads : int, optional
        Requests of one batch are split across this many threads (numpy and pocketfft release
        the GIL). Default: ``min(2, cores)``. Results do not depend on it.
    """

    name = "fft"
    renderer = "cpu"

    def __init__(self, threads: int | None = None) -> None:
        self.threads = max(1, threads if threads is not None else min(2, os.cpu_count() or 1))
        self._pool: ThreadPoolExecutor | None = None
        self._block = 0
        self._fft_shape = (0, 0)
        self._field_shape = (0, 0)
        self._spectrum: NDArray[np.complex64] | None = None  # set while a job is prepared
        self._maps: dict[str, _Map] = {}  # "source" and, for transfer, "guide"
        self._energy: dict[tuple[str, bytes], tuple[NDArray[np.float32], float, float]] = {}
        self._lock = threading.Lock()

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        height, width, _ = source.shape
        # Circular correlation on an FFT grid at least the source's size is exact at every
        # valid position: y + u never passes the last source row.
        nh, nw = sfft.next_fast_len(height), sfft.next_fast_len(width, real=True)
        self._block = block
        self._fft_shape = (nh, nw)
        self._field_shape = (height - block + 1, width - block + 1)
        self._energy = {}
        self._maps = {}
        for name, image in (("source", source), ("guide", guide)):
            if image is None:
                continue
            planes = np.ascontiguousarray(image.transpose(2, 0, 1), dtype=np.float32)
            squares = (planes.astype(np.float64) ** 2).sum(axis=0)
            self._maps[name] = _Map(
                spectrum_conj=np.conj(sfft.rfft2(planes, s=(nh, nw))),
                energy_spectrum=sfft.rfft2(squares, s=(nh, nw)),
                norm=float(np.sqrt(squares.sum())),
            )
        self._spectrum = self._maps["source"].spectrum_conj
        if self.threads > 1 and self._pool is None:
            self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="quilting-fft")

    def _mask_energy(
        self, mask: NDArray[np.float32], map_name: str = "source"
    ) -> tuple[NDArray[np.float32], float, float]:
        """``sum M * X^2`` at every candidate position of a map X (cached per mask and map),
        its error bound and its maximum."""
        key = (map_name, mask.tobytes())
        cached = self._energy.get(key)
        if cached is not None:
            return cached
        with self._lock:  # worker threads may ask for the same new mask at once
            cached = self._energy.get(key)
            if cached is None:
                energy_spectrum = self._maps[map_name].energy_spectrum
                kernel = sfft.rfft2(mask.astype(np.float64), s=self._fft_shape)
                full = sfft.irfft2(np.conj(kernel) * energy_spectrum, s=self._fft_shape)
                exact = full[: self._field_shape[0], : self._field_shape[1]]
                top = float(np.abs(exact).max())
                # float32 storage rounds by half an ulp; the float64 FFT adds ~1e-16 relative.
                cached = (exact.astype(np.float32), top * (_EPS32 + 1e-12), top)
                self._energy[key] = cached  # one assignment: readers see all or nothing
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

    def _correlate(
        self, kernels: NDArray[np.float32], spectrum_conj: NDArray[np.complex64]
    ) -> NDArray[np.float32]:
        """``sum_c corr(kernel_c, map_c)`` at every candidate position.

        Parameters
        ----------
        kernels : ndarray, shape (n, C, B, B), float32
        spectrum_conj : ndarray, shape (C, Nh, Nw // 2 + 1), complex64
            Conjugated spectrum of the map.

        Returns
        -------
        ndarray, shape (n, H - B + 1, W - B + 1), float32
        """
        nh, nw = self._fft_shape
        fh, fw = self._field_shape
        # 2-D transform of a B x B kernel on the Nh x Nw grid: rows first on the B non-zero
        # rows only, then columns.
        spectra = sfft.fft(sfft.rfft(kernels, n=nw, axis=-1), n=nh, axis=-2, overwrite_x=True)
        # sum_c conj(K_c) S_c = conj(sum_c K_c conj(S_c)): one conjugation of the sum instead
        # of one per channel.
        product = spectra[:, 0]
        product *= spectrum_conj[0]
        for channel in range(1, spectra.shape[1]):
            spectra[:, channel] *= spectrum_conj[channel]
            product += spectra[:, channel]
        np.conjugate(product, out=product)
        columns = sfft.ifft(product, axis=-2, overwrite_x=True)[:, :fh]
        cross: NDArray[np.float32] = sfft.irfft(columns, n=nw, axis=-1)[:, :, :fw]
        return cross

    def _fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        nh, nw = self._fft_shape
        gamma = _SAFETY * _EPS32 * math.log2(nh * nw)
        masks = np.stack([r.mask for r in requests])  # (n, B, B)
        templates = np.stack([r.template for r in requests])  # (n, B, B, C)
        kernels = templates * masks[..., None]
        constants = np.einsum(
            "nyxc,nyx->n", templates.astype(np.float64) ** 2, masks.astype(np.float64)
        )
        # The previous-pass term correlates with the same source: fold it into the kernel,
        # K = M T + w P, and its energy into a second, unmasked energy field.
        weights = np.array([r.previous_weight for r in requests], dtype=np.float32)
        for k, request in enumerate(requests):
            if request.previous is not None and request.previous_weight > 0:
                kernels[k] += weights[k] * request.previous
                constants[k] += request.previous_weight * float(
                    (request.previous.astype(np.float64) ** 2).sum()
                )
        kernels = np.ascontiguousarray(kernels.transpose(0, 3, 1, 2))
        values = self._correlate(kernels, self._maps["source"].spectrum_conj)
        kernel_norms = np.sqrt(np.einsum("ncyx,ncyx->n", kernels, kernels, dtype=np.float64))
        bounds = 2 * gamma * kernel_norms * self._maps["source"].norm
        values *= -2
        ones = np.ones(masks.shape[1:], dtype=np.float32)
        for k, request in enumerate(requests):
            terms = [(self._mask_energy(request.mask), 1.0)]
            if weights[k] > 0:
                terms.append((self._mask_energy(ones), float(weights[k])))
            top = constants[k]
            for (energy, error, largest), weight in terms:
                values[k] += energy if weight == 1.0 else np.float32(weight) * energy
                bounds[k] += weight * error
                top += weight * largest
            values[k] += np.float32(constants[k])
            # Each float32 addition above rounds by half an ulp of at most `top`.
            bounds[k] += (2 + len(terms)) * _EPS32 * top
        self._add_guide_terms(requests, values, bounds, gamma)
        return FieldBatch(values, bounds)

    def _add_guide_terms(
        self,
        requests: Sequence[CostRequest],
        values: NDArray[np.float32],
        bounds: NDArray[np.float64],
        gamma: float,
    ) -> None:
        """Add ``w_G * sum (G_S - G)^2`` to the fields of the requests that have a guide."""
        guided = [k for k, r in enumerate(requests) if r.guide is not None and r.guide_weight > 0]
        if not guided:
            return
        if "guide" not in self._maps:
            raise ValueError("a request has a guide term but prepare() got no guide map")
        guides = np.stack([requests[k].guide for k in guided])  # type: ignore[misc]
        kernels = np.ascontiguousarray(guides.transpose(0, 3, 1, 2))
        cross = self._correlate(kernels, self._maps["guide"].spectrum_conj)
        energy, error, largest = self._mask_energy(
            np.ones(guides.shape[1:3], dtype=np.float32), "guide"
        )
        norm = self._maps["guide"].norm
        for row, k in enumerate(guided):
            weight = requests[k].guide_weight
            constant = float((guides[row].astype(np.float64) ** 2).sum())
            term = energy - 2 * cross[row] + np.float32(constant)
            values[k] += np.float32(weight) * term
            kernel_norm = float(np.sqrt((kernels[row].astype(np.float64) ** 2).sum()))
            top = largest + constant
            bounds[k] += weight * (2 * gamma * kernel_norm * norm + error + 4 * _EPS32 * top)
            bounds[k] += 2 * _EPS32 * (float(np.abs(values[k]).max()) + weight * top)

    def close(self) -> None:
        self._spectrum = None
        self._maps = {}
        self._energy = {}
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None
