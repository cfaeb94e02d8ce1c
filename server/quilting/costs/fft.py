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

import itertools
import math
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from quilting.core import kernels as compiled
from quilting.core.fields import CostRequest, FieldBatch, Shortlist

T = TypeVar("T")

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
    energy_norm: float  # Frobenius norm of sum_c X_c^2


@dataclass(frozen=True)
class _Terms:
    """The parts of a batch's fields: ``field[k] = (cross[k][:, :W] + energies[k]) +
    constants[k]`` in float32, within ``bounds[k]`` of the exact costs."""

    cross: NDArray[np.float32]  # (n, H - B + 1, Nw): the correlation's rows, -2 sum K S
    energies: list[NDArray[np.float32]]  # n fields (H - B + 1, W - B + 1), shared by kind
    constants: NDArray[np.float32]  # (n,)
    bounds: NDArray[np.float64]  # (n,)


class FFTBackend:
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
        self._joint: NDArray[np.complex64] | None = None  # source and guide spectra, stacked
        self._with_energy: NDArray[np.complex64] | None = None  # source and its energy, stacked
        self._fold: NDArray[np.float64] | None = None  # (K, C): guide = source @ fold.T
        self._fold_residual = 0.0  # largest |guide - source @ fold.T|

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
                energy_norm=float(np.sqrt((squares**2).sum())),
            )
        self._spectrum = self._maps["source"].spectrum_conj
        self._joint = self._with_energy = None
        self._fold, self._fold_residual = None, 0.0
        if guide is not None:
            self._fold, self._fold_residual = _linear_fit(source, guide)
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
        done = self._map(self._dense, requests)
        if not done:  # no requests: an empty batch, as the reference backend gives
            shape = (0, *self._field_shape)
            return FieldBatch(np.zeros(shape, dtype=np.float32), np.zeros(0, dtype=np.float64))
        if len(done) == 1:
            return done[0]
        return FieldBatch(
            np.concatenate([d.values for d in done]), np.concatenate([d.error_bound for d in done])
        )

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        """Each chunk's fields reduced to shortlists on the thread that computed them, so the
        reduction runs in parallel too and whole fields never leave the worker."""

        scale = 1 + tolerance

        def reduce(part: Sequence[CostRequest]) -> list[Shortlist]:
            terms = self._terms(part)
            listed = []
            for k, energy in enumerate(terms.energies):
                bound = float(terms.bounds[k])
                index, values = compiled.field_shortlist(
                    terms.cross[k], energy, terms.constants[k], bound, scale, min_candidates
                )
                listed.append(Shortlist(index, values, bound))
            return listed

        return [entry for part in self._map(reduce, requests) for entry in part]

    def _map(
        self, work: Callable[[Sequence[CostRequest]], T], requests: Sequence[CostRequest]
    ) -> list[T]:
        """``work`` over chunks of ``requests``, on the pool's threads, in order."""
        if self._spectrum is None:
            raise RuntimeError("prepare() must be called before fields()")
        # Chunks of a few requests keep each chunk's spectra in cache (measured: 4-8 per chunk
        # is ~15 % faster than 16 or more) and give the threads work to share: as many chunks
        # as make them at most _CHUNK long, rounded up to a multiple of the threads, and of
        # equal length to within one (17 requests on 2 threads run as 5+4 and 4+4, not 6+6
        # and 5).
        n = len(requests)
        if not n:
            return []
        count = min(n, self.threads * -(-n // (self.threads * _CHUNK)))
        edges = [n * k // count for k in range(count + 1)]
        parts = [requests[a:b] for a, b in itertools.pairwise(edges)]
        if self._pool is None or len(parts) == 1:
            return [work(part) for part in parts]
        return list(self._pool.map(work, parts))

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
        ndarray, shape (n, H - B + 1, Nw), float32
            The correlation's rows; the first ``W - B + 1`` columns are the field's.
        """
        nh, nw = self._fft_shape
        fh = self._field_shape[0]
        # 2-D transform of a B x B kernel on the Nh x Nw grid: rows first on the B non-zero
        # rows only, then columns.
        spectra = sfft.fft(sfft.rfft(kernels, n=nw, axis=-1), n=nh, axis=-2, overwrite_x=True)
        # sum_c conj(K_c) S_c = conj(sum_c K_c conj(S_c)), in one compiled pass.
        product = np.empty((spectra.shape[0], nh, spectra.shape[3]), dtype=np.complex64)
        compiled.spectral_sum(spectra, spectrum_conj, product)
        columns = sfft.ifft(product, axis=-2, overwrite_x=True)[:, :fh]
        cross: NDArray[np.float32] = sfft.irfft(columns, n=nw, axis=-1)
        return cross

    def _dense(self, requests: Sequence[CostRequest]) -> FieldBatch:
        """The dense fields of ``requests``: cross term, then energy, then constant, in
        float32."""
        terms = self._terms(requests)
        values = terms.cross[:, :, : self._field_shape[1]]
        for k, energy in enumerate(terms.energies):
            values[k] += energy
        values += terms.constants[:, None, None]
        return FieldBatch(values, terms.bounds)

    def _terms(self, requests: Sequence[CostRequest]) -> _Terms:
        one_off = [not r.shared_mask and r.previous is None and r.guide is None for r in requests]
        if all(one_off):
            return self._one_off_terms(requests)
        if not any(one_off):
            return self._shared_terms(requests)
        # Both kinds in one chunk: each its own way, so that a request's terms never depend on
        # what shares its chunk (the thread count cuts the chunks) and no one-off mask's
        # energy is kept.
        alone = [k for k, flag in enumerate(one_off) if flag]
        shared = [k for k, flag in enumerate(one_off) if not flag]
        parts = (
            (alone, self._one_off_terms([requests[k] for k in alone])),
            (shared, self._shared_terms([requests[k] for k in shared])),
        )
        cross = np.empty((len(requests), *parts[0][1].cross.shape[1:]), dtype=np.float32)
        energies: list[NDArray[np.float32]] = [parts[0][1].energies[0]] * len(requests)
        constants = np.empty(len(requests), dtype=np.float32)
        bounds = np.empty(len(requests), dtype=np.float64)
        for members, terms in parts:
            cross[members] = terms.cross
            constants[members] = terms.constants
            bounds[members] = terms.bounds
            for k, energy in zip(members, terms.energies, strict=True):
                energies[k] = energy
        return _Terms(cross, energies, constants, bounds)

    def _shared_terms(self, requests: Sequence[CostRequest]) -> _Terms:
        """The terms of requests whose masks are shared (every block of one overlap kind in a
        pass), with a previous pass's or a guide's term: the energy is one float64 field per
        mask, kept for the next requests."""
        nh, nw = self._fft_shape
        gamma = _SAFETY * _EPS32 * math.log2(nh * nw)
        source = self._maps["source"]
        masks, templates, constants = _stacked(requests)
        kernels = templates * masks[..., None]
        # The previous-pass term correlates with the same source: fold it into the kernel,
        # K = M T + w P, and its energy into a second, unmasked energy field.
        weights = np.array([r.previous_weight if r.previous is not None else 0.0 for r in requests])
        with_previous = np.flatnonzero(weights > 0)
        if with_previous.size:
            previous = np.stack(
                [requests[k].previous for k in with_previous.tolist()]  # type: ignore[misc]
            )
            scale = weights[with_previous]
            kernels[with_previous] += scale.astype(np.float32)[:, None, None, None] * previous
            constants[with_previous] += scale * np.einsum(
                "myxc,myxc->m", previous, previous, dtype=np.float64
            )
        guided = [k for k, r in enumerate(requests) if r.guide is not None and r.guide_weight > 0]
        if guided and "guide" not in self._maps:
            raise ValueError("a request has a guide term but prepare() got no guide map")
        guides = np.zeros((len(requests), *masks.shape[1:], 0), dtype=np.float32)
        guide_weights = np.zeros(len(requests))
        fold_error = np.zeros(len(requests))
        if guided:
            guide = self._maps["guide"]
            guides = np.zeros(
                (len(requests), *masks.shape[1:], guide.spectrum_conj.shape[0]), dtype=np.float32
            )
            guides[guided] = np.stack([requests[k].guide for k in guided])  # type: ignore[misc]
            guide_weights[guided] = [requests[k].guide_weight for k in guided]
            constants += guide_weights * np.einsum("nyxk,nyxk->n", guides, guides, dtype=np.float64)
            guides *= guide_weights.astype(np.float32)[:, None, None, None]
        spectrum, norm = source.spectrum_conj, source.norm
        if guided and self._fold is not None:
            # G_S = S L: the guide's cross term is a correlation with the source too.
            kernels += guides @ self._fold.astype(np.float32)
            # |sum w G (G_S - S L)| <= w |G| |residual over the block|.
            block_residual = math.sqrt(guides.shape[1] * guides.shape[2] * guides.shape[3])
            fold_error = (
                2
                * np.sqrt(np.einsum("nyxk,nyxk->n", guides, guides, dtype=np.float64))
                * block_residual
                * self._fold_residual
            )
            kernels = np.ascontiguousarray(kernels.transpose(0, 3, 1, 2))
        elif guided:
            # Separate maps, one inverse transform: the channel sum runs over both.
            kernels = np.ascontiguousarray(
                np.concatenate([kernels, guides], axis=-1).transpose(0, 3, 1, 2)
            )
            spectrum = self._joint_spectrum()
            norm = math.hypot(source.norm, self._maps["guide"].norm)
        else:
            kernels = np.ascontiguousarray(kernels.transpose(0, 3, 1, 2))
        # -2 sum K S: the factor goes into the (small) kernels rather than over the field.
        kernels *= np.float32(-2)
        cross = self._correlate(kernels, spectrum)
        kernel_norms = np.sqrt(np.einsum("ncyx,ncyx->n", kernels, kernels, dtype=np.float64))
        bounds = gamma * kernel_norms * norm + fold_error
        ones = np.ones(masks.shape[1:], dtype=np.float32)
        # Requests sharing a mask and weights (every block of one overlap kind in a pass)
        # share their energy field.
        groups: dict[tuple[int, float, float], list[int]] = {}
        for k, request in enumerate(requests):
            key = (id(request.mask), float(weights[k]), float(guide_weights[k]))
            groups.setdefault(key, []).append(k)
        energies: list[NDArray[np.float32]] = [ones] * len(requests)
        for (_, previous_weight, guide_weight), members in groups.items():
            energy, error, top = self._energy_sum(
                requests[members[0]].mask, ones, previous_weight, guide_weight
            )
            for k in members:
                energies[k] = energy
            # Two float32 additions, each rounding by half an ulp of at most the total.
            bounds[members] += error + 2 * _EPS32 * (top + constants[members])
        return _Terms(cross, energies, constants.astype(np.float32), bounds)

    def _one_off_terms(self, requests: Sequence[CostRequest]) -> _Terms:
        """The terms of requests whose masks are their own (a fill's): the energy
        ``sum M S^2`` is correlated with the cross term, as one more channel (the mask against
        the source's energy map), in the same float32 transforms, instead of a float64 field
        per mask that would be used once and kept."""
        nh, nw = self._fft_shape
        gamma = _SAFETY * _EPS32 * math.log2(nh * nw)
        source = self._maps["source"]
        masks, templates, constants = _stacked(requests)
        channels = templates.shape[3]
        kernels = np.empty((len(requests), channels + 1, *masks.shape[1:]), dtype=np.float32)
        kernels[:, :channels] = (templates * masks[..., None]).transpose(0, 3, 1, 2)
        kernels[:, :channels] *= np.float32(-2)
        kernels[:, channels] = masks
        cross = self._correlate(kernels, self._energy_joint())
        kernel_norms = np.sqrt(np.einsum("ncyx,ncyx->n", kernels, kernels, dtype=np.float64))
        norm = math.hypot(source.norm, source.energy_norm)
        # The transforms' round-off, the energy spectrum's rounding to complex64 (half an ulp
        # of each coefficient) and the two float32 additions of the field (the cross term is at
        # most |K| |map| by Cauchy-Schwarz).
        bounds = (gamma + 3 * _EPS32) * kernel_norms * norm + 2 * _EPS32 * constants
        zeros = np.zeros(self._field_shape, dtype=np.float32)
        return _Terms(cross, [zeros] * len(requests), constants.astype(np.float32), bounds)

    def _energy_joint(self) -> NDArray[np.complex64]:
        """The source's conjugated spectra and its energy map's, as one (C + 1)-channel
        stack (float32)."""
        with self._lock:
            if self._with_energy is None:
                source = self._maps["source"]
                energy = np.conj(source.energy_spectrum).astype(np.complex64)[None]
                self._with_energy = np.concatenate([source.spectrum_conj, energy])
            return self._with_energy

    def _energy_sum(
        self,
        mask: NDArray[np.float32],
        ones: NDArray[np.float32],
        previous_weight: float,
        guide_weight: float,
    ) -> tuple[NDArray[np.float32], float, float]:
        """``sum M S^2 + w_P sum S^2 + w_G sum G_S^2`` at every candidate position, its error
        bound and its maximum. Every block of one overlap kind in a pass shares the weights, so
        this is cached like the energies it sums."""
        if previous_weight == 0 and guide_weight == 0:
            return self._mask_energy(mask)
        key = ("sum", mask.tobytes() + np.array([previous_weight, guide_weight]).tobytes())
        cached = self._energy.get(key)
        if cached is not None:
            return cached
        terms = [(self._mask_energy(mask), 1.0)]
        if previous_weight > 0:
            terms.append((self._mask_energy(ones), previous_weight))
        if guide_weight > 0:
            terms.append((self._mask_energy(ones, "guide"), guide_weight))
        total = np.zeros(terms[0][0][0].shape, dtype=np.float64)
        error = top = 0.0
        for (energy, energy_error, largest), weight in terms:
            total += weight * energy.astype(np.float64)
            error += weight * energy_error
            top += weight * largest
        # Rounding the float64 sum to float32: half an ulp of at most `top`.
        cached = (total.astype(np.float32), error + (_EPS32 + 1e-12) * top, top)
        with self._lock:
            self._energy[key] = cached
        return cached

    def _joint_spectrum(self) -> NDArray[np.complex64]:
        """The source's and the guide's conjugated spectra as one (C + K)-channel stack."""
        with self._lock:
            if self._joint is None:
                self._joint = np.concatenate(
                    [self._maps["source"].spectrum_conj, self._maps["guide"].spectrum_conj]
                )
            return self._joint

    def close(self) -> None:
        self._spectrum = None
        self._joint = self._with_energy = None
        self._fold = None
        self._maps = {}
        self._energy = {}
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None


def _stacked(
    requests: Sequence[CostRequest],
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float64]]:
    """The requests' masks (n, B, B), templates (n, B, B, C) and constants ``sum M T^2``
    (n,), float64: what every batch's terms start from."""
    masks = np.stack([r.mask for r in requests])
    templates = np.stack([r.template for r in requests])
    constants = np.einsum(
        "nyxc,nyx->n", templates.astype(np.float64) ** 2, masks.astype(np.float64)
    )
    return masks, templates, constants


def _linear_fit(
    source: NDArray[np.float32], guide: NDArray[np.float32]
) -> tuple[NDArray[np.float64] | None, float]:
    """``(L, r)`` with ``guide ~ source @ L.T`` pixel by pixel and r the largest residual, when
    the guide is such a combination of the source's channels up to rounding (the luminance of
    the texture is); ``(None, 0)`` otherwise.

    Parameters
    ----------
    source : ndarray, shape (H, W, C)
    guide : ndarray, shape (H, W, K)
    """
    pixels = source.reshape(-1, source.shape[2]).astype(np.float64)
    wanted = guide.reshape(-1, guide.shape[2]).astype(np.float64)
    solution, *_ = np.linalg.lstsq(pixels, wanted, rcond=None)
    residual = float(np.abs(pixels @ solution - wanted).max(initial=0.0))
    scale = float(np.abs(wanted).max(initial=0.0))
    # A few float32 ulps of the guide's values: rounding, not a different map.
    if residual > 8 * _EPS32 * max(scale, 1e-30):
        return None, 0.0
    return np.ascontiguousarray(solution.T), residual
