"""A fill's layout: every block it placed, where it came from and which pixels it took.

What :class:`quilting.core.layout.Layout` is to a synthesis, this is to a fill or an
extension (:mod:`quilting.core.fill`): the blocks follow the hole, not a grid, and each took
the pixels of its side of a minimum cut, so a block is stored with its place, its source
position and the mask of the pixels it took. Replaying them in order gives every output
pixel's source pixel (:meth:`FillLayout.provenance`), which fills a companion map (normals,
roughness) the way the image was filled (:meth:`FillLayout.apply`, the hard selection: the
image's blend is not repeated) and draws the seams (:meth:`FillLayout.seam_mask`). It is
saved as JSON (:meth:`FillLayout.to_json`), the masks as packed bits.
"""

from __future__ import annotations

import base64
import json
import os
import re
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import InvalidImageError, LayoutError

#: The ``kind`` a fill layout's JSON carries (a synthesis layout has none).
KIND = "fill"
VERSION = 1
Source = Literal["image", "texture"]


@dataclass(frozen=True)
class FillLayout:
    """The blocks of one fill, in the order they were placed.

    Attributes
    ----------
    shape : (int, int)
        The output's (height, width).
    source_shape : (int, int)
        (height, width) of what the blocks came from: the image (a fill), the input (an
        extension) or the texture.
    source : {"image", "texture"}
        ``"image"``: the blocks came from the image being filled (or, with ``placed``, the
        input being extended), whose companion :meth:`apply` takes; ``"texture"``: from a
        separate texture, whose companion it needs too.
    placed : (int, int) or None
        For an extension, where the input's top-left corner lies in the output.
    block : int
        Block side B.
    corners : ndarray of intp, shape (n, 2)
        Each block's (y, x) in the output.
    positions : ndarray of intp, shape (n, 2)
        Each block's (y, x) in the source.
    owned : ndarray of bool, shape (n, B, B)
        The pixels each block took.
    meta : dict
        The fill's options and operation, for the record.
    """

    shape: tuple[int, int]
    source_shape: tuple[int, int]
    source: Source
    placed: tuple[int, int] | None
    block: int
    corners: NDArray[np.intp]
    positions: NDArray[np.intp]
    owned: NDArray[np.bool_]
    meta: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def empty(cls, shape: tuple[int, int], options: object = None) -> FillLayout:
        """The layout of a fill that placed nothing (an empty mask): the image as it is."""
        to_dict = getattr(options, "to_dict", None)
        return cls(
            shape=shape,
            source_shape=shape,
            source="image",
            placed=None,
            block=1,
            corners=np.zeros((0, 2), dtype=np.intp),
            positions=np.zeros((0, 2), dtype=np.intp),
            owned=np.zeros((0, 1, 1), dtype=bool),
            meta={"operation": "fill", **(to_dict() if callable(to_dict) else {})},
        )

    def provenance(self) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
        """``(rows, cols)``, shape (H, W): the source pixel each output pixel is a copy of in
        the hard selection; a pixel no block took is the image's own (itself, or for an
        extension its place in the input), or -1 when the blocks came from a texture."""
        rows = np.full(self.shape, -1, dtype=np.int32)
        cols = np.full(self.shape, -1, dtype=np.int32)
        if self.source == "image":
            top, left = self.placed or (0, 0)
            ys, xs = np.indices(self.shape, dtype=np.int32)
            inside = (
                (ys >= top)
                & (ys < top + self.source_shape[0])
                & (xs >= left)
                & (xs < left + self.source_shape[1])
            )
            rows[inside], cols[inside] = ys[inside] - top, xs[inside] - left
        offsets = np.indices((self.block, self.block), dtype=np.int32)
        for (y, x), (sy, sx), take in zip(
            self.corners.tolist(), self.positions.tolist(), self.owned, strict=True
        ):
            window = np.s_[y : y + self.block, x : x + self.block]
            rows[window][take] = sy + offsets[0][take]
            cols[window][take] = sx + offsets[1][take]
        return rows, cols

    def apply(
        self, companion: NDArray[np.generic], texture_companion: NDArray[np.generic] | None = None
    ) -> NDArray[np.generic]:
        """A companion map filled the way the image was.

        Parameters
        ----------
        companion : ndarray, shape (h, w) or (h, w, K)
            The image's companion: of the image's size for a fill, of the input's for an
            extension; its pixels outside the hole are kept.
        texture_companion : ndarray, shape (h', w') or (h', w', K), optional
            The texture's companion, when the blocks came from a texture.

        Returns
        -------
        ndarray, shape (H, W) or (H, W, K), the companion's dtype
            Every filled pixel copied from where the image's came from (the hard selection).
        """
        own = self.shape if self.placed is None else self.source_shape
        if companion.shape[:2] != own:
            what = "image's" if self.placed is None else "size of the image that was extended,"
            raise InvalidImageError(
                f"the companion is {companion.shape[1]}x{companion.shape[0]}; it must be the "
                f"{what} {own[1]}x{own[0]}"
            )
        rows, cols = self.provenance()
        if self.source == "image":
            return companion[rows, cols]
        if texture_companion is None:
            raise InvalidImageError(
                "this fill took its blocks from a texture: give the texture's companion too"
            )
        if texture_companion.shape[:2] != self.source_shape:
            raise InvalidImageError(
                f"the texture's companion is {texture_companion.shape[1]}x"
                f"{texture_companion.shape[0]}; it must be the texture's size, "
                f"{self.source_shape[1]}x{self.source_shape[0]}"
            )
        if texture_companion.shape[2:] != companion.shape[2:]:
            raise InvalidImageError("the texture's companion must have the companion's channels")
        out = companion.copy()
        taken = rows >= 0
        out[taken] = texture_companion[rows[taken], cols[taken]]
        return out

    def seam_mask(self) -> NDArray[np.bool_]:
        """(H, W) bool: the pixels on a seam, where a neighbour's source pixel is not the
        source pixel's neighbour (both sides of the cut are marked)."""
        rows, cols = self.provenance()
        taken = rows >= 0
        seam = np.zeros(self.shape, dtype=bool)
        for axis in (0, 1):
            step_rows = np.diff(rows, axis=axis) != (1 if axis == 0 else 0)
            step_cols = np.diff(cols, axis=axis) != (0 if axis == 0 else 1)
            first = taken[:-1] if axis == 0 else taken[:, :-1]
            second = taken[1:] if axis == 0 else taken[:, 1:]
            # Two pixels no block took (a texture fill's known pixels) are the image's own.
            cut = (step_rows | step_cols) & (first | second)
            if axis == 0:
                seam[:-1] |= cut
                seam[1:] |= cut
            else:
                seam[:, :-1] |= cut
                seam[:, 1:] |= cut
        return seam

    def to_json(self) -> str:
        """The layout as JSON (the masks as base64 of their packed bits)."""
        bits = np.packbits(self.owned.ravel()).tobytes()
        return json.dumps(
            {
                "kind": KIND,
                "version": VERSION,
                "shape": list(self.shape),
                "source_shape": list(self.source_shape),
                "source": self.source,
                "placed": None if self.placed is None else list(self.placed),
                "block": self.block,
                "corners": self.corners.ravel().tolist(),
                "positions": self.positions.ravel().tolist(),
                "owned": base64.b64encode(bits).decode("ascii"),
                "meta": self.meta,
            }
        )

    @classmethod
    def from_json(cls, text: str | bytes) -> FillLayout:
        """A layout from :meth:`to_json`'s JSON; a malformed one raises
        :class:`~quilting.core.errors.LayoutError` saying what is wrong."""
        try:
            data = json.loads(text)
            if data.get("kind") != KIND or data.get("version") != VERSION:
                raise LayoutError(f"not a fill layout of version {VERSION}")
            shape = _pair(data["shape"], "shape")
            source_shape = _pair(data["source_shape"], "source_shape")
            block = int(data["block"])
            corners = np.asarray(data["corners"], dtype=np.intp).reshape(-1, 2)
            positions = np.asarray(data["positions"], dtype=np.intp).reshape(-1, 2)
            count = corners.shape[0]
            bits = np.frombuffer(base64.b64decode(data["owned"], validate=True), dtype=np.uint8)
            owned = np.unpackbits(bits)[: count * block * block].astype(bool)
            owned = owned.reshape(count, block, block)
            placed = None if data["placed"] is None else _pair(data["placed"], "placed")
            source = data["source"]
        except LayoutError:
            raise
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise LayoutError(f"malformed fill layout: {exc}") from None
        if source not in ("image", "texture"):
            raise LayoutError(f"malformed fill layout: source {source!r}")
        if positions.shape != corners.shape or block < 1:
            raise LayoutError("malformed fill layout: corners and positions differ in count")
        if count and (
            (corners < 0).any()
            or (corners + block > np.array(shape)).any()
            or (positions < 0).any()
            or (positions + block > np.array(source_shape)).any()
        ):
            raise LayoutError("malformed fill layout: a block lies outside its image")
        return cls(
            shape=shape,
            source_shape=source_shape,
            source=source,
            placed=placed,
            block=block,
            corners=corners,
            positions=positions,
            owned=owned,
            meta=dict(data.get("meta") or {}),
        )

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`to_json` to ``path``."""
        with open(path, "w", encoding="utf-8") as out:
            out.write(self.to_json())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> FillLayout:
        """Read a layout :meth:`save` wrote."""
        with open(path, encoding="utf-8") as source:
            return cls.from_json(source.read())


#: The start of a fill layout's JSON (a synthesis layout's never starts with a ``kind``).
_FILL_HEAD = re.compile(r'\A\s*\{\s*"kind"\s*:\s*"fill"')


def is_fill_layout(text: str | bytes) -> bool:
    """Whether layout JSON is a fill's (else a synthesis's), from its first characters."""
    head = text[:64] if isinstance(text, str) else text[:64].decode("utf-8", "replace")
    return _FILL_HEAD.match(head) is not None


def _pair(value: Any, name: str) -> tuple[int, int]:
    first, second = (int(v) for v in value)
    if first < 0 or second < 0:
        raise LayoutError(f"malformed fill layout: {name} {value!r}")
    return first, second
