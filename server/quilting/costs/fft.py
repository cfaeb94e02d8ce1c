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
from collections.abc import Sequence

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from quilting.core.fields import CostRequest, FieldBatch

#: Unit round-off of float32.
_EPS32 = float(np.finfo(np.float32).eps) / 2
#: Safety factor over the usual FFT error estimate eps * log2(N) * |K| * |S|; measured errors
#: on random and real textures stay below 1/20 of the resulting bound (tests/costs).
_SAFETY = 8.0


class FFTBackend:
    """Cost fields by FFT correlation with cached source spectra.

    Parameters
    ----------
    workers : int
        Threads per transform (``scipy.fft`` ``workers``). Results do not depend on it.
    """

    name = "fft"

    def __init__(self, workers: int = 1) -> None:
        self.workers = workers
        self._block = 0
        self._fft_shape = (0, 0)
        self._field_shape = (0, 0)
        self._spectrum: NDArray[np.complex64] | None = None  # (C, Nh, Nw // 2 + 1)
        self._energy_spectrum: NDArray[np.complex128] | None = None  # of sum_c S_c^2
        self._energy: dict[bytes, NDArray[np.float64]] = {}
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
        self._spectrum = sfft.rfft2(planes, s=(nh, nw), workers=self.workers)
        squares = (planes.astype(np.float64) ** 2).sum(axis=0)
        self._energy_spectrum = sfft.rfft2(squares, s=(nh, nw), workers=self.workers)
        self._energy = {}
        self._source_norm = float(np.sqrt(squares.sum()))

    def _mask_energy(self, mask: NDArray[np.float32]) -> NDArray[np.float64]:
        """``sum M * S^2`` at every candidate position, float64, cached per mask."""
        key = mask.tobytes()
        energy = self._energy.get(key)
        if energy is None:
            assert self._energy_spectrum is not None
            kernel = sfft.rfft2(mask.astype(np.float64), s=self._fft_shape, workers=self.workers)
            full = sfft.irfft2(
                np.conj(kernel) * self._energy_spectrum, s=self._fft_shape, workers=self.workers
            )
            energy = np.ascontiguousarray(full[: self._field_shape[0], : self._field_shape[1]])
            self._energy[key] = energy
        return energy

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        if self._spectrum is None:
            raise RuntimeError("prepare() must be called before fields()")
        nh, nw = self._fft_shape
        fh, fw = self._field_shape
        masks = np.stack([r.mask for r in requests])  # (n, B, B)
        kernels = np.stack([r.template for r in requests]) * masks[..., None]  # (n, B, B, C)
        kernels = np.ascontiguousarray(kernels.transpose(0, 3, 1, 2))  # (n, C, B, B)
        # 2-D transform of a B x B kernel on the Nh x Nw grid: rows first on the B non-zero
        # rows only, then columns.
        spectra = sfft.fft(
            sfft.rfft(kernels, n=nw, axis=-1, workers=self.workers),
            n=nh,
            axis=-2,
            workers=self.workers,
        )
        product = np.conj(spectra[:, 0]) * self._spectrum[0]
        for channel in range(1, spectra.shape[1]):
            product += np.conj(spectra[:, channel]) * self._spectrum[channel]
        columns = sfft.ifft(product, axis=-2, workers=self.workers, overwrite_x=True)[:, :fh]
        cross = sfft.irfft(columns, n=nw, axis=-1, workers=self.workers)[:, :, :fw]

        template_energy = np.einsum(
            "nyxc,nyx->n", np.stack([r.template for r in requests]).astype(np.float64) ** 2, masks
        )
        values = np.empty((len(requests), fh, fw), dtype=np.float64)
        bounds = np.empty(len(requests), dtype=np.float64)
        kernel_norms = np.sqrt(np.einsum("ncyx,ncyx->n", kernels, kernels, dtype=np.float64))
        gamma = _SAFETY * _EPS32 * math.log2(nh * nw)
        for k, request in enumerate(requests):
            energy = self._mask_energy(request.mask)
            np.multiply(cross[k], -2.0, out=values[k])
            values[k] += energy
            values[k] += template_energy[k]
            # float64 terms add ~1e-16 relative; the float32 cross term dominates the error.
            bounds[k] = 2 * gamma * kernel_norms[k] * self._source_norm + 1e-12 * (
                float(energy.max()) + template_energy[k]
            )
        return FieldBatch(values, bounds)

    def close(self) -> None:
        self._spectrum = None
        self._energy_spectrum = None
        self._energy = {}
