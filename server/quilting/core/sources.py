"""Where candidate blocks come from: several examples, each rotated and mirrored.

A job may take its blocks from several example images of the same kind (three photos of the
same gravel) and from the eight rotations and mirrors of each (the dihedral group of the
square), as extra material for isotropic textures. Every (example, transform) pair is a
*placement*: the transformed example laid into one *atlas* image with a margin of excluded
pixels around it. The engine quilts from the atlas as from one texture; the margin's pixels are
excluded (:mod:`quilting.core.exclusion`), so no candidate block ever straddles two placements,
and every backend's cost field over the atlas holds, at each placement's candidates, exactly the
field of that transformed example. The tolerance rule over the atlas is therefore the rule over
the union of the examples' candidates: the best block across all of them, chosen the same way.

A layout records the atlas (:class:`SourceSet`) and block positions in it; a block's source is
its placement (example, transform) and its position inside that placement
(:meth:`SourceSet.locate`). Companion maps are laid into the same atlas by :meth:`SourceSet.build`;
for tangent-space normal maps the vectors turn with the pixels (:func:`turn_normals`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import InvalidImageError, InvalidParameterError, LayoutError
from quilting.core.exclusion import excluded_pixels
from quilting.core.pixels import PixelFormat, as_channels

#: The eight transforms of the square, in canonical order. Image axes: x to the right, y down.
#: 'rot90' turns the picture a quarter counter-clockwise as seen on screen, 'rot270' clockwise;
#: 'flip_x' mirrors left-right, 'flip_y' top-bottom; 'transpose' mirrors about the main
#: diagonal (top-left to bottom-right), 'transverse' about the other one.
TRANSFORMS: tuple[str, ...] = (
    "identity",
    "rot90",
    "rot180",
    "rot270",
    "flip_x",
    "flip_y",
    "transpose",
    "transverse",
)
#: Named sets of transforms: 'flips' keeps the axes (mirrors and the half turn), 'rotations'
#: the quarter turns, 'all' the whole group.
PRESETS: dict[str, tuple[str, ...]] = {
    "none": ("identity",),
    "flips": ("identity", "flip_x", "flip_y", "rot180"),
    "rotations": ("identity", "rot90", "rot180", "rot270"),
    "all": TRANSFORMS,
}
#: The transforms that swap an image's height and width.
SWAPPING = frozenset({"rot90", "rot270", "transpose", "transverse"})


def transformed_shape(shape: tuple[int, int], name: str) -> tuple[int, int]:
    """(height, width) of an image of ``shape`` once transformed by ``name``."""
    return (shape[1], shape[0]) if name in SWAPPING else (shape[0], shape[1])


#: How each transform moves an in-plane vector (dx, dy), x right and y down: the rows of the
#: 2 x 2 signed permutation ``A`` with ``(dx', dy') = A (dx, dy)``.
_VECTOR: dict[str, tuple[tuple[int, int], tuple[int, int]]] = {
    "identity": ((1, 0), (0, 1)),
    "rot90": ((0, 1), (-1, 0)),
    "rot180": ((-1, 0), (0, -1)),
    "rot270": ((0, -1), (1, 0)),
    "flip_x": ((-1, 0), (0, 1)),
    "flip_y": ((1, 0), (0, -1)),
    "transpose": ((0, 1), (1, 0)),
    "transverse": ((0, -1), (-1, 0)),
}
#: Companion kinds whose first three channels are tangent-space normals, and the sign of
#: their y axis in image coordinates (OpenGL's green points up, DirectX's down).
NORMAL_KINDS: dict[str, int] = {"normal": -1, "normal_dx": 1}


def transform_names(value: Any) -> tuple[str, ...]:
    """Validate ``transforms`` and normalize it to transform names in canonical order.

    Parameters
    ----------
    value : str or sequence of str
        A preset ('none', 'flips', 'rotations', 'all'), a comma-separated list of names of
        :data:`TRANSFORMS` and presets (their union), or a sequence of them. 'identity' is
        always included.

    Returns
    -------
    tuple of str
    """
    allowed = f"one of {', '.join(repr(p) for p in PRESETS)}, or a list of {', '.join(TRANSFORMS)}"
    if isinstance(value, str):
        if value in PRESETS:
            return PRESETS[value]
        items: Sequence[Any] = [part.strip() for part in value.split(",") if part.strip()]
    elif isinstance(value, Sequence) and not isinstance(value, bytes):
        items = value
    else:
        raise InvalidParameterError("transforms", value, allowed)
    names: set[str] = set()
    for item in items:
        if isinstance(item, str) and item in PRESETS:
            names.update(PRESETS[item])  # 'flips,rot90': a preset and more
        elif isinstance(item, str) and item in TRANSFORMS:
            names.add(item)
        else:
            raise InvalidParameterError(
                "transforms", value, allowed, f"{item!r} is neither a transform nor a preset"
            )
    names.add("identity")
    return tuple(t for t in TRANSFORMS if t in names)


def transformed(image: NDArray[Any], name: str) -> NDArray[Any]:
    """``image`` (H, W, ...) under the transform ``name`` (a view where numpy gives one)."""
    if name == "identity":
        return image
    if name.startswith("rot"):
        return np.rot90(image, int(name[3:]) // 90)
    if name == "flip_x":
        return image[:, ::-1]
    if name == "flip_y":
        return image[::-1]
    if name == "transpose":
        return image.swapaxes(0, 1)
    if name == "transverse":
        return np.rot90(image, 2).swapaxes(0, 1)
    raise ValueError(f"unknown transform {name!r}")


def turn_normals(image: NDArray[Any], name: str, y_sign: int = -1) -> NDArray[Any]:
    """A tangent-space normal map under the transform ``name``: the pixels move as
    :func:`transformed` moves them and each vector's x and y turn with them.

    A component is stored as ``(n + 1) / 2`` of the dtype's range, so the vectors' turn is a
    signed permutation of the first two channels and a negated component is ``max - v``
    (255 - v for 8 bits, 1 - v for floats): exact, no rounding.

    Parameters
    ----------
    image : ndarray, shape (H, W, C), C >= 3
        Channels x, y, z (and any others, which move with the pixels only).
    name : str
        One of :data:`TRANSFORMS`.
    y_sign : {-1, 1}
        The map's y axis in image coordinates: -1 when green points up (OpenGL, Blender), 1
        when it points down (DirectX).

    Returns
    -------
    ndarray, shape as :func:`transformed` gives, same dtype
    """
    moved = np.array(transformed(image, name), copy=True)
    top = np.iinfo(image.dtype).max if image.dtype.kind in "ui" else 1
    (axx, axy), (ayx, ayy) = _VECTOR[name]
    # In image axes the vector is (x, y_sign * y); A turns it; back to the map's axes.
    rows = ((axx, axy * y_sign), (ayx * y_sign, ayy))
    source = [moved[..., 0].copy(), moved[..., 1].copy()]
    for out, (a, b) in enumerate(rows):
        coefficient, channel = (a, 0) if a else (b, 1)
        moved[..., out] = source[channel] if coefficient > 0 else top - source[channel]
    return moved


@dataclass(frozen=True)
class Placement:
    """One transformed example in the atlas.

    Attributes
    ----------
    example : int
        Index of the example in the list given.
    transform : str
        One of :data:`TRANSFORMS`.
    y, x : int
        Top-left corner of the transformed example in the atlas.
    height, width : int
        Its size once transformed (a quarter turn swaps the example's sides).
    """

    example: int
    transform: str
    y: int
    x: int
    height: int
    width: int


@dataclass(frozen=True)
class SourceSet:
    """The atlas of a job's sources: which example and transform lies where.

    Attributes
    ----------
    examples : tuple of (int, int)
        (height, width) of each example as given.
    placements : tuple of Placement
        Example by example, each example's transforms in :data:`TRANSFORMS` order.
    shape : (int, int)
        (height, width) of the atlas.
    margin : int
        Pixels of excluded border around each placement (1, or the block in walk mode, whose
        continuations read past a block and find the placement's reflection there).
    """

    examples: tuple[tuple[int, int], ...]
    placements: tuple[Placement, ...]
    shape: tuple[int, int]
    margin: int

    @classmethod
    def plan(
        cls,
        examples: Sequence[tuple[int, int]],
        transforms: Sequence[str],
        margin: int = 1,
    ) -> SourceSet:
        """Lay every (example, transform) into an atlas, row by row (shelf packing).

        Parameters
        ----------
        examples : sequence of (int, int)
            (height, width) of each example.
        transforms : sequence of str
            Names of :data:`TRANSFORMS`, applied to every example.
        margin : int
            Excluded pixels around each placement, >= 1.

        Returns
        -------
        SourceSet
        """
        sizes = []
        for index, (h, w) in enumerate(examples):
            for name in transforms:
                sizes.append((index, name, transformed_shape((h, w), name)))
        cells = [(h + 2 * margin, w + 2 * margin) for _, _, (h, w) in sizes]
        # A near-square atlas: shelves as wide as the widest cell or the square root of the
        # total area, whichever is larger.
        shelf = max(max(w for _, w in cells), math.isqrt(sum(h * w for h, w in cells) - 1) + 1)
        placements, y, x, row_height, width = [], 0, 0, 0, 0
        for (index, name, (h, w)), (ch, cw) in zip(sizes, cells, strict=True):
            if x + cw > shelf:
                y, x, row_height = y + row_height, 0, 0
            placements.append(Placement(index, name, y + margin, x + margin, h, w))
            x += cw
            row_height = max(row_height, ch)
            width = max(width, x)
        return cls(tuple(map(tuple, examples)), tuple(placements), (y + row_height, width), margin)  # type: ignore[arg-type]

    @classmethod
    def for_job(
        cls, examples: Sequence[tuple[int, int]], transforms: str, block: int, *, walk: bool
    ) -> SourceSet:
        """The atlas a job of these options quilts from: every example under every transform
        of ``transforms`` (:func:`transform_names`), with a margin of 1 pixel, or of a block
        in walk mode (whose continuations read past a block into the placement's reflection)."""
        return cls.plan(examples, transform_names(transforms), block if walk else 1)

    @property
    def trivial(self) -> bool:
        """One example, untransformed: the engine quilts from it directly, as it always has."""
        return len(self.placements) == 1 and self.placements[0].transform == "identity"

    def build(self, views: Sequence[NDArray[Any]], kind: str = "blend") -> NDArray[Any]:
        """The atlas of ``views``: each example transformed into its placements.

        Parameters
        ----------
        views : sequence of ndarray, each shape (h_i, w_i, C)
            One image per example, each of its example's size, all of one dtype and channel
            count (the examples themselves, or companion maps of them).
        kind : str
            A companion kind: 'normal' or 'normal_dx' turn the vectors of the first three
            channels with the pixels (:func:`turn_normals`); any other moves pixels only.

        Returns
        -------
        ndarray, shape (atlas height, atlas width, C), the views' dtype
            Zero outside the placements, except in walk mode's margins (margin > 1), which
            hold each placement's reflection.
        """
        channels, dtype = views[0].shape[2], views[0].dtype
        atlas = np.zeros((*self.shape, channels), dtype=dtype)
        m = self.margin
        for p in self.placements:
            view = views[p.example]
            if kind in NORMAL_KINDS:
                moved = turn_normals(view, p.transform, NORMAL_KINDS[kind])
            else:
                moved = transformed(view, p.transform)
            if m > 1:
                padded = np.pad(moved, ((m, m), (m, m), (0, 0)), mode="reflect")
                atlas[p.y - m : p.y + p.height + m, p.x - m : p.x + p.width + m] = padded
            else:
                atlas[p.y : p.y + p.height, p.x : p.x + p.width] = moved
        return atlas

    def excluded(self) -> NDArray[np.bool_]:
        """Atlas pixels no block may contain: everything outside the placements, (H, W)."""
        outside = np.ones(self.shape, dtype=bool)
        for p in self.placements:
            outside[p.y : p.y + p.height, p.x : p.x + p.width] = False
        return outside

    def candidate_weights(self, block: int, weights: Sequence[float]) -> NDArray[np.float64]:
        """The weight of every candidate corner of the atlas: its example's, 0 elsewhere.

        Returns
        -------
        ndarray of float64, shape ((H - B + 1) * (W - B + 1),)
            Flat, indexed like the cost fields.
        """
        height, width = self.shape[0] - block + 1, self.shape[1] - block + 1
        field = np.zeros((height, width), dtype=np.float64)
        for p in self.placements:
            field[p.y : p.y + p.height - block + 1, p.x : p.x + p.width - block + 1] = weights[
                p.example
            ]
        return field.ravel()

    def locate(self, positions: NDArray[np.integer]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Which placement holds each atlas position, and the position inside it.

        Parameters
        ----------
        positions : ndarray of int, shape (..., 2)
            Atlas (y, x) of block corners.

        Returns
        -------
        placement : ndarray of intp, shape (...)
            Index into :attr:`placements` (-1 where no placement holds the corner).
        local : ndarray of intp, shape (..., 2)
            (y, x) of the corner in that transformed example.
        """
        corners: NDArray[np.intp] = np.asarray(positions, dtype=np.intp)
        placement: NDArray[np.intp] = np.full(corners.shape[:-1], -1, dtype=np.intp)
        local = corners.copy()
        y, x = corners[..., 0], corners[..., 1]
        for index, p in enumerate(self.placements):
            inside = (y >= p.y) & (y < p.y + p.height) & (x >= p.x) & (x < p.x + p.width)
            placement[inside] = index
            local[inside] -= (p.y, p.x)
        return placement, local

    def to_json(self) -> dict[str, Any]:
        return {
            "examples": [list(e) for e in self.examples],
            "margin": self.margin,
            "shape": list(self.shape),
            "placements": [
                {
                    "example": p.example,
                    "transform": p.transform,
                    "y": p.y,
                    "x": p.x,
                    "height": p.height,
                    "width": p.width,
                }
                for p in self.placements
            ],
        }

    @classmethod
    def from_json(cls, data: Any) -> SourceSet:
        """Read :meth:`to_json`'s form; a malformed one raises :class:`LayoutError`."""
        try:
            examples = tuple((int(h), int(w)) for h, w in data["examples"])
            placements = tuple(
                Placement(
                    int(p["example"]),
                    str(p["transform"]),
                    int(p["y"]),
                    int(p["x"]),
                    int(p["height"]),
                    int(p["width"]),
                )
                for p in data["placements"]
            )
            shape = (int(data["shape"][0]), int(data["shape"][1]))
            margin = int(data["margin"])
        except (KeyError, TypeError, ValueError, IndexError, OverflowError) as exc:
            raise LayoutError(f"layout sources are malformed: {exc!r}") from None
        sources = cls(examples, placements, shape, margin)
        for p in placements:
            if not 0 <= p.example < len(examples) or p.transform not in TRANSFORMS:
                raise LayoutError(f"layout sources hold an impossible placement: {p}")
            if (p.height, p.width) != transformed_shape(examples[p.example], p.transform) or not (
                margin <= p.y and p.y + p.height + margin <= shape[0]
                and margin <= p.x and p.x + p.width + margin <= shape[1]
            ):  # fmt: skip
                raise LayoutError(f"layout sources hold a placement outside the atlas: {p}")
        if margin < 1 or not placements:
            raise LayoutError("layout sources have no placement or no margin")
        return sources


@dataclass(frozen=True)
class Examples:
    """A job's examples once validated: the texture the engine quilts from, and what it is.

    Attributes
    ----------
    view : ndarray, shape (h, w, C)
        The one texture as given, or the atlas of the examples' placements, in the examples'
        dtype.
    fmt : PixelFormat
        How the examples were given (one dtype and channel count for all).
    sources : SourceSet or None
        The atlas's plan; None when ``view`` is the one texture, untransformed.
    excluded : ndarray of bool, shape (h, w), or None
        Pixels no block may contain: the user's exclusions and the atlas's margins.
    weights : tuple of float or None
        One per example, when they differ.
    """

    view: NDArray[Any]
    fmt: PixelFormat
    sources: SourceSet | None
    excluded: NDArray[np.bool_] | None
    weights: tuple[float, ...] | None


def read_examples(
    texture: object,
    *,
    block: int,
    transforms: str = "none",
    weights: Sequence[float] | None = None,
    exclude_colors: tuple[Any, ...] = (),
    source_mask: object = None,
    walk: bool = False,
) -> Examples:
    """Validate a job's examples and lay them out for the engine.

    Parameters
    ----------
    texture : ndarray or sequence of ndarray
        One texture, or several examples (each (h_i, w_i) or (h_i, w_i, C)) of one dtype and
        channel count, each at least ``block`` on its shorter side.
    block : int
        The job's block side.
    transforms : str
        The ``transforms`` option (:func:`transform_names`).
    weights : sequence of float, optional
        The ``weights`` option: one per example.
    exclude_colors : tuple
        The ``exclude_colors`` option, applied to every example.
    source_mask : ndarray or sequence of ndarray, optional
        Black = never used; one per example, each of its example's size.
    walk : bool
        Walk mode: the placements get a margin of a block, holding their reflection, so that
        the walk's continuations past a block read what they read at one texture's edge.

    Returns
    -------
    Examples
    """
    several = isinstance(texture, list | tuple)
    items = list(texture) if several else [texture]  # type: ignore[call-overload]
    if not items:
        raise InvalidImageError("no texture given: pass an image or a list of examples")
    views = []
    fmt: PixelFormat | None = None
    for index, item in enumerate(items):
        name = f"texture {index}" if several else "texture"
        view, item_fmt = as_channels(item, name)
        if fmt is not None and (item_fmt.dtype, item_fmt.channels) != (fmt.dtype, fmt.channels):
            raise InvalidImageError(
                f"{name} is {item_fmt.channels}-channel {item_fmt.dtype}, but texture 0 is "
                f"{fmt.channels}-channel {fmt.dtype}: the examples must be of one kind"
            )
        if block > min(view.shape[:2]):
            raise InvalidParameterError(
                "block",
                block,
                f"3..{min(view.shape[:2])} for the {view.shape[1]}x{view.shape[0]} {name}",
                f"the block is larger than the {name}",
            )
        fmt = fmt or item_fmt
        views.append(view)
    assert fmt is not None
    masks = _per_example(source_mask, len(views), several)
    if weights is not None and len(weights) != len(views):
        raise InvalidParameterError(
            "weights", list(weights), f"{len(views)} number(s), one per example"
        )
    differ = weights is not None and len(set(weights)) > 1
    plan = SourceSet.for_job([v.shape[:2] for v in views], transforms, block, walk=walk)
    if plan.trivial:
        excluded = excluded_pixels(views[0], exclude_colors, masks[0])
        return Examples(views[0], fmt, None, excluded, None)
    atlas = plan.build(views)
    excluded = plan.excluded()
    for placement in plan.placements:
        own = excluded_pixels(
            transformed(views[placement.example], placement.transform),
            exclude_colors,
            None if masks[placement.example] is None
            else transformed(masks[placement.example], placement.transform),
        )  # fmt: skip
        if own is not None:
            window = (slice(placement.y, placement.y + placement.height),
                      slice(placement.x, placement.x + placement.width))  # fmt: skip
            excluded[window] |= own
    return Examples(atlas, fmt, plan, excluded, tuple(weights) if differ else None)  # type: ignore[arg-type]


def _per_example(mask: object, count: int, several: bool) -> list[Any]:
    """The source mask of each example (None where there is none)."""
    if mask is None:
        return [None] * count
    if not several:
        return [mask]
    if not isinstance(mask, list | tuple) or len(mask) != count:
        raise InvalidImageError(
            f"with {count} examples, source_mask must be a list of {count} masks (None for an "
            "example without one)"
        )
    return list(mask)
