"""Engine options: frozen, keyword-only dataclasses validated at construction.

Each field carries its documentation and allowed range in ``metadata`` so that the CLI, the
README table and (later) the HTTP schema are generated from one place instead of written twice.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal, TypeVar, get_args

from quilting.core.errors import InvalidParameterError
from quilting.core.exclusion import ColorRange, color_ranges
from quilting.core.sources import PRESETS, TRANSFORMS, transform_names

Mode = Literal["auto", "random", "overlap", "cut", "walk", "alpha"]
MODES: tuple[str, ...] = get_args(Mode)
ErrorKind = Literal["rgb", "luminance"]
ERRORS: tuple[str, ...] = get_args(ErrorKind)
Blend = Literal["none", "poisson"]
BLENDS: tuple[str, ...] = get_args(Blend)
#: Largest discard probability: at 1 every candidate would go.
MAX_DISCARD = 0.99
Continuation = Literal["auto", "allow", "avoid"]
CONTINUATIONS: tuple[str, ...] = get_args(Continuation)
Tileable = Literal["both", "x", "y"]
TILEABLE: tuple[str, ...] = get_args(Tileable)
TileBlend = Literal["none", "poisson"]
TILE_BLENDS: tuple[str, ...] = get_args(TileBlend)
TransferMode = Literal["overlap", "cut"]
TRANSFER_MODES: tuple[str, ...] = get_args(TransferMode)
Correspondence = Literal["luminance", "blurred", "orientation", "custom"]
CORRESPONDENCES: tuple[str, ...] = get_args(Correspondence)
MAX_ITERATIONS = 8
MatteMode = Literal["auto", "random", "overlap", "cut", "alpha"]
MATTE_MODES: tuple[str, ...] = get_args(MatteMode)
MAX_CLUSTERS = 256
MattingMethod = Literal["lkm", "cf", "knn"]
MATTING_METHODS: tuple[str, ...] = get_args(MattingMethod)
ForegroundKind = Literal["ml", "photo"]
FOREGROUND_KINDS: tuple[str, ...] = get_args(ForegroundKind)

#: Largest output side accepted by the engine (the service sets tighter limits of its own).
MAX_SIDE = 65_536
MAX_SEED = 2**64 - 1


def _meta(doc: str, **limits: Any) -> dict[str, Any]:
    return {"doc": doc, **limits}


class _Declared:
    """Options whose fields declare their limits in metadata: checked at construction."""

    def _check_fields(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]  # every subclass is a dataclass
            _check_field(f.name, getattr(self, f.name), f.metadata)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict of every field (what PNG metadata and the layout record)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]

    @classmethod
    def resolve(
        cls: type[DeclaredT],
        options: DeclaredT | None = None,
        overrides: Mapping[str, Any] | None = None,
        *,
        caller: str = "",
    ) -> DeclaredT:
        """The options a call runs with: ``options`` (default: every field's default) with
        the keyword ``overrides`` put in, validated once.

        Parameters
        ----------
        options : this class, optional
            The caller's options object; another options class is refused.
        overrides : mapping of str to object, optional
            Field names and values; a name that is no field of this class is refused, with
            the closest field's name when there is one (as Python does for a misspelt keyword).
        caller : str
            The function the overrides were given to, for the messages.

        Raises
        ------
        TypeError
            ``options`` of another class, or a keyword that is no field.
        InvalidParameterError
            A value out of its field's range.
        """
        given = dict(overrides or {})
        names = [f.name for f in fields(cls)]  # type: ignore[arg-type]  # subclasses are dataclasses
        where = f"{caller}()" if caller else cls.__name__
        for name in given:
            if name not in names:
                close = difflib.get_close_matches(name, names, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise TypeError(f"{where} got an unexpected keyword argument {name!r}{hint}")
        if options is None:
            return cls(**given)
        if not isinstance(options, cls):
            raise TypeError(
                f"{where}: options must be a {cls.__name__}, not {type(options).__name__}"
            )
        return replace(options, **given) if given else options  # type: ignore[type-var]


DeclaredT = TypeVar("DeclaredT", bound=_Declared)


@dataclass(frozen=True, kw_only=True)
class QuiltOptions(_Declared):
    """Parameters shared by synthesis and transfer: blocks, matching, seams and randomness.

    Defaults are the paper's: overlap = block / 6, tolerance 0.1 (Efros & Freeman 2001, §2.2).
    Construction validates every field; an invalid value raises
    :class:`~quilting.core.errors.InvalidParameterError` naming the field and its range.
    Checks that need the texture (block larger than the texture) happen in ``synthesize``.
    """

    block: int = field(
        default=48,
        metadata=_meta(
            "Side of the square blocks in pixels, at most the texture's shorter side. Larger "
            "blocks keep larger structures intact; smaller ones give more variety but can cut "
            "structures apart. A block a bit larger than the texture's biggest feature is a good "
            "start.",
            ge=3,
            le=MAX_SIDE,
        ),
    )
    overlap: int | None = field(
        default=None,
        metadata=_meta(
            "Width of the band shared by neighbouring blocks; None means block // 6 (at least 1; "
            "the paper's sixth of the block). Must be less than block / 2. Wider overlaps match "
            "more context and hide seams better, and cost more.",
            ge=1,
            optional=True,
        ),
    )
    blend: Blend = field(
        default="poisson",
        metadata=_meta(
            "How a cut's two sides are joined: 'none', as the cut leaves them (every output "
            "pixel a texture pixel); 'poisson' (the default), the gradients across the cut "
            "replaced by the mean of both sides' and each block's cell solved for them by a "
            "screened Poisson solve (a brightness or colour step is taken off over a few "
            "pixels each side of the cut, the texture's detail is kept). "
            "Modes that cut (cut, overlap, random, alpha, transfer); walk mode blends by "
            "feather. On a torus (tileable) the seams across the wrap are blended too. "
            "Companion maps: see apply_layout's kind.",
            choices=BLENDS,
        ),
    )
    tolerance: float = field(
        default=0.1,
        metadata=_meta(
            "Blocks whose overlap error is within (1 + tolerance) x the best are equally likely "
            "to be chosen (the paper: 0.1). 0 always takes the best match; larger values add "
            "variety and show more seams.",
            ge=0.0,
            le=10.0,
        ),
    )
    mode: Mode = field(
        default="auto",
        metadata=_meta(
            "'auto': 'alpha' for an RGBA texture, else 'cut'. 'random': random blocks, "
            "straight edges (Efros & Freeman 2001, Fig. 2a); 'overlap': blocks matched on the "
            "overlap, straight edges (Fig. 2b); 'cut': matched, joined along the minimum-error "
            "boundary cut (Fig. 2c); 'walk': random blocks joined along a minimum-resistance walk, "
            "the old side filled from the previous blocks' continuations in the texture and "
            "blended over 'feather' pixels; 'alpha': alpha quilting of an RGBA texture: "
            "premultiplied colour matched and cut, the alpha histogram kept, blocks "
            "drawn by their seams' cost (see epsilon, histogram_weight, eta).",
            choices=MODES,
        ),
    )
    seed: int = field(
        default=0,
        metadata=_meta(
            "Random seed. The same seed and options give the same bytes on every backend.",
            ge=0,
            le=MAX_SEED,
        ),
    )
    backend: str = field(
        default="auto",
        metadata=_meta(
            "Cost-field backend: 'auto' (a hardware GPU's 'gl', else 'fft'; the QUILTING_BACKEND "
            "environment variable can say which), 'fft' (CPU FFT), 'gl' (GLSL compute shaders) "
            "or 'reference' (slow direct sums). A backend asked for by name that cannot run is "
            "an error, never a silent fallback. Every backend chooses the same blocks.",
        ),
    )
    min_candidates: int = field(
        default=3,
        metadata=_meta(
            "Floor of the tolerance rule: the threshold is (1 + tolerance) x the cost of the "
            "min_candidates-th best block, so at least that many blocks stay acceptable. It "
            "stops a zero-error verbatim continuation from copying the source; 1 is the "
            "paper's rule exactly.",
            ge=1,
            le=10_000,
        ),
    )

    error: ErrorKind = field(
        default="rgb",
        metadata=_meta(
            "What the overlap error and the seams compare: 'rgb', every channel of the "
            "texture (gray, RGB or RGBA), or 'luminance' (Rec. 601; colour is then free to "
            "vary where brightness matches).",
            choices=ERRORS,
        ),
    )
    discard: float = field(
        default=0.0,
        metadata=_meta(
            "Probability with which each candidate block is dropped before the tolerance "
            "rule (random discarding; decided by a hash of the block's seed and the "
            "candidate, so the same seed gives the same result on every backend). The best "
            "match itself may go, which breaks loops of blocks that keep following each other "
            "in the source.",
            ge=0.0,
            le=MAX_DISCARD,
        ),
    )

    exclude_colors: tuple[ColorRange, ...] = field(
        default=(),
        metadata=_meta(
            "Colour ranges never to use: a list of [low, high] pairs, each a "
            "colour in the texture's own values (0..255 for 8-bit, 0..65535 for 16-bit; one "
            "value for gray, three or four for RGB(A), three comparing an RGBA texture's colour "
            "only). No block containing a pixel inside a range is ever chosen; a source_mask "
            "image (black = never used) does the same by region. Exclusions that leave no whole "
            "block are an error that says so.",
            kind="color_ranges",
        ),
    )

    def __post_init__(self) -> None:
        # JSON gives lists: one normalized, hashable form.
        object.__setattr__(self, "exclude_colors", color_ranges(self.exclude_colors))
        self._check_fields()
        _check_overlap(self.overlap, self.block)
        if 2 * self.resolved_overlap >= self.block:  # only block < 3 could get here
            raise InvalidParameterError("block", self.block, f">= 3, got {self.block}")

    def resolved_mode(self, channels: int, image: str = "texture") -> Mode:
        """The mode used for an ``image`` of ``channels`` channels (``auto`` decided;
        ``alpha`` refused without an alpha channel, offering this class's other modes)."""
        if self.mode == "auto":
            return "alpha" if channels == 4 else "cut"
        if self.mode == "alpha" and channels != 4:
            offered = next(f for f in fields(self) if f.name == "mode").metadata["choices"]
            raise InvalidParameterError(
                "mode",
                "alpha",
                " or ".join(", ".join(repr(m) for m in offered if m != "alpha").rsplit(", ", 1))
                + f" for {image} without alpha",
                f"alpha quilting needs RGBA; {image} has {channels} channels",
            )
        mode: Mode = self.mode  # a transfer's modes are among synthesis's
        return mode

    @property
    def resolved_overlap(self) -> int:
        """The overlap actually used: ``overlap`` or ``max(1, block // 6)``."""
        return self.overlap if self.overlap is not None else max(1, self.block // 6)


def _check_overlap(overlap: int | None, block: int) -> None:
    """Refuse an overlap of half the block or more (neighbours' overlaps would meet)."""
    if overlap is not None and 2 * overlap >= block:
        raise InvalidParameterError(
            "overlap",
            overlap,
            f"1..{(block - 1) // 2} for block={block}",
            "the overlap must be less than half the block",
        )


def _check_field(name: str, value: Any, meta: Any) -> None:
    """Validate one option value against the limits declared in its field metadata."""
    choices = meta.get("choices")
    if choices is not None:
        if value not in choices:
            raise InvalidParameterError(name, value, "one of " + ", ".join(map(repr, choices)))
        return
    if meta.get("kind") in ("color_ranges", "transforms", "weights"):
        return  # checked and normalized in __post_init__
    if meta.get("kind") == "direction":
        _check_direction(name, value)
        return
    if meta.get("kind") == "bool":
        if not isinstance(value, bool):
            raise InvalidParameterError(name, value, "true or false")
        return
    if "ge" not in meta:
        if not isinstance(value, str):
            raise InvalidParameterError(name, value, "a string")
        return
    if value is None and meta.get("optional"):
        return
    lo, hi = meta.get("ge"), meta.get("le")
    allowed = f"{lo}..{hi}" if hi is not None else f">= {lo}"
    is_float_field = isinstance(lo, float)
    if isinstance(value, bool) or not isinstance(value, int | float):
        kind = "a number" if is_float_field else "an integer"
        raise InvalidParameterError(name, value, f"{kind} in {allowed}")
    if not is_float_field and not isinstance(value, int):
        raise InvalidParameterError(name, value, f"an integer in {allowed}")
    if isinstance(value, float) and not math.isfinite(value):
        raise InvalidParameterError(name, value, f"a finite number in {allowed}")
    if value < lo or (hi is not None and value > hi):
        raise InvalidParameterError(name, value, allowed)
    step = meta.get("multiple_of")
    if step is not None and value % step:
        kind = "an even number" if step == 2 else f"a multiple of {step}"
        raise InvalidParameterError(name, value, f"{kind} in {allowed}")


def _check_direction(name: str, value: Any) -> None:
    """A direction towards the viewer's side: three finite numbers, z > 0 (or None)."""
    if value is None:
        return
    allowed = "None or [x, y, z] with z > 0 (x right, y up, z towards the viewer)"
    numbers = isinstance(value, tuple) and len(value) == 3
    if not numbers or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        raise InvalidParameterError(name, value, allowed)
    if value[2] <= 0:
        raise InvalidParameterError(
            name, value, allowed, "the light must shine from in front of the surface"
        )


# Alpha quilting's fields, declared once: synthesis and matting both take them.
HISTOGRAM_WEIGHT = _meta(
    "Alpha mode: lambda of the alpha quilting error (eq. 1), per overlap pixel. A candidate pays "
    "lambda x overlap pixels x (1 - Bhattacharyya coefficient between its alpha "
    "histogram and the texture's, 100 bins), so blocks keep the texture's mix of "
    "opaque and clear: without it the premultiplied error prefers nearly clear blocks and "
    "the output empties. 0 matches premultiplied colour alone.",
    ge=0.0,
    le=1000.0,
)
EPSILON = _meta(
    "Alpha mode: candidates within (1 + epsilon) x the best error (the "
    "min_candidates-th best) are kept (the paper's 0.02); 'tolerance' is not used there.",
    ge=0.0,
    le=10.0,
)
ETA = _meta(
    "Alpha mode: among the kept candidates one is drawn with probability "
    "exp(-eta x E), E its seam's cumulative error (colour in 0..1). 0 draws "
    "uniformly; larger favours the cleanest seams. The paper gives no value.",
    ge=0.0,
    le=1e6,
)


def canonical_transforms(value: Any) -> str:
    """``transforms`` in its one stored form: a preset's name, or the transforms' names
    comma-separated in canonical order (:func:`quilting.core.sources.transform_names`)."""
    names = transform_names(value)
    preset = next((p for p, members in PRESETS.items() if members == names), None)
    return preset if preset is not None else ",".join(names)


def example_weights(value: Any) -> tuple[float, ...] | None:
    """Validate ``weights``: None, or finite numbers > 0 (one per example, counted when the
    examples are known)."""
    allowed = "None or a list of numbers > 0, one per example"
    if value is None:
        return None
    if isinstance(value, str | bytes) or not isinstance(value, tuple | list) or not value:
        raise InvalidParameterError("weights", value, allowed)
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
            raise InvalidParameterError("weights", value, allowed, f"{v!r} is not a number > 0")
    return tuple(float(v) for v in value)


CONTINUATION_META = _meta(
    "Matched modes: whether a block may continue the source of a neighbour placed before it "
    "(left, top, top-left, top-right) verbatim (a zero-error match the tolerance rule always "
    "accepts). 'allow': the paper's rule; 'avoid': that block is dropped from the acceptable "
    "ones whenever another is acceptable, so verbatim copies stay about one block across "
    "instead of runs of blocks; 'auto' (the default): 'avoid' when there is more material "
    "than one example as it is (several examples, or transforms other than 'none'), else "
    "'allow'. Extra material alone leaves the copies as large (runs of continuations do not "
    "depend on it). Measured at 512x512 from 128x128 samples: texeval's largest copy 0.31 -> "
    "0.19 of the sample on gravel, 0.20 -> 0.10 with transforms='all', coherence as good; "
    "over 18 textures without transforms 0.45x the largest copy, coherence (p95) +0.02, and "
    "more visible seams on a brick wall photo.",
    choices=CONTINUATIONS,
)
# The sources' fields, declared once: synthesis and Wang tiles both take them.
TRANSFORMS_META = _meta(
    "Rotated and mirrored copies of every example offered as extra candidates: 'none' (the "
    "default), 'flips' (mirrored left-right, top-bottom and both), 'rotations' (the four "
    "quarter turns), 'all' (the eight rotations and mirrors of the square), or a "
    "comma-separated list of " + ", ".join(TRANSFORMS) + ". Up to eight times the material "
    "for isotropic textures (gravel, stars, foliage from above), at the cost of the "
    "orientation of textures that have one (wood grain, bricks); the cost grows with the "
    "total source area. The layout records each block's transform, and companion maps "
    "turn with it (normal maps' vectors too, see apply_layout's kind).",
    kind="transforms",
)
MATTING_META = _meta(
    "How the alpha is found when a photo comes with a trimap or scribbles instead of an "
    "alpha channel: 'lkm' (the default), large-kernel matting (He, Sun and Tang 2010): the "
    "closest alphas in our measurements (5-20x less error than 'cf' on smoke over a sky or "
    "grass) and the least memory, about 1.7x the time of 'cf'; 'cf', closed-form matting "
    "(Levin, Lischinski and Weiss 2008, the alpha quilting paper's choice); 'knn', KNN "
    "matting (Chen, Li and Tang 2013): the fastest, softer alphas, about 4 KiB of memory a "
    "pixel.",
    choices=MATTING_METHODS,
)
WEIGHTS_META = _meta(
    "With several examples: how much to prefer each, one number > 0 per example. Among the "
    "blocks the tolerance rule accepts (and among the random ones of random and walk modes) "
    "a block is drawn with probability proportional to its example's weight. None (the "
    "default): every acceptable block equally likely.",
    kind="weights",
)


@dataclass(frozen=True, kw_only=True)
class SynthesisOptions(QuiltOptions):
    """Parameters of texture synthesis by image quilting: the shared ones (see
    :class:`QuiltOptions`) plus tileable output and the walk cut's settings."""

    tileable: Tileable | None = field(
        default=None,
        metadata=_meta(
            "Make the output repeat seamlessly: 'both', 'x' (left-right) or 'y' (top-bottom). "
            "The grid of blocks wraps on a torus, so the last column (row) is matched and cut "
            "against the first. The output has exactly the requested size (each tileable side "
            "at least the block); the join across the wrap is cut through a strip between the "
            "overlap and block - overlap wide, the overlap widened by a pixel or two for sizes "
            "that would make it narrower (the layout records the one used). Not with mode "
            "'walk'.",
            choices=(None, *TILEABLE),
        ),
    )
    max_run: int = field(
        default=5,
        metadata=_meta(
            "Walk mode: the most pixels the walk cut may run straight along one row or one "
            "column. Smaller keeps the cut closer to the block's edge.",
            ge=1,
            le=MAX_SIDE,
        ),
    )
    feather: int = field(
        default=4,
        metadata=_meta(
            "Walk mode: width in pixels of the blend across the cut (0 or 1: a hard cut; at "
            "most the block is used).",
            ge=0,
            le=MAX_SIDE,
        ),
    )

    seam_sampling: float = field(
        default=0.0,
        metadata=_meta(
            "Cut mode: among the blocks within tolerance draw one with probability "
            "exp(-seam_sampling x E / median E), E the cost of the minimum-error seam it "
            "would be joined along (factored sampling, as alpha mode's eta, relative to the "
            "candidates' median so that one value suits every texture's contrast). 0 (the "
            "default) draws uniformly, the paper's rule. About 4 favours the cheapest joins: "
            "fewer new patterns along the seams of structured textures (bricks, weaves, "
            "spots), at the price of more and larger verbatim copies (continuations of the "
            "neighbours join at no cost) and, on sparse textures, steeper steps across "
            "the seams.",
            ge=0.0,
            le=100.0,
        ),
    )
    histogram_weight: float = field(default=0.05, metadata=HISTOGRAM_WEIGHT)
    epsilon: float = field(default=0.02, metadata=EPSILON)
    eta: float = field(default=20.0, metadata=ETA)
    continuation: Continuation = field(default="auto", metadata=CONTINUATION_META)
    transforms: str = field(default="none", metadata=TRANSFORMS_META)
    weights: tuple[float, ...] | None = field(default=None, metadata=WEIGHTS_META)
    matting: MattingMethod = field(default="lkm", metadata=MATTING_META)

    def __post_init__(self) -> None:
        object.__setattr__(self, "transforms", canonical_transforms(self.transforms))
        object.__setattr__(self, "weights", example_weights(self.weights))
        super().__post_init__()
        if self.tileable is not None and self.mode == "walk":
            raise InvalidParameterError(
                "tileable",
                self.tileable,
                "None with mode='walk'",
                "the walk cut fills from the blocks before it and cannot close a torus; use "
                "mode 'cut', 'overlap' or 'random' for tileable output",
            )

    def resolved_continuation(self, examples: int) -> Continuation:
        """The rule used with ``examples`` examples: ``auto`` decided (``avoid`` when the
        job has more material than one example as it is, where the copies would otherwise
        stay as large as from one; the paper's ``allow`` otherwise)."""
        if self.continuation != "auto":
            return self.continuation
        return "avoid" if examples > 1 or self.transforms != "none" else "allow"


@dataclass(frozen=True, kw_only=True)
class TransferOptions(QuiltOptions):
    """Parameters of texture transfer (Efros & Freeman 2001, §3): synthesis options plus the
    correspondence, the weight alpha between texture and target, and the number of passes.

    ``block`` and ``overlap`` are those of the first pass; each further pass reduces both by a
    third, down to ``min_block``, and a final shading (``shade``) brings the output's coarse
    luminance closer to the target's (see :func:`quilting.core.transfer.schedule` and
    :func:`quilting.core.transfer.shade_towards`).
    """

    block: int = field(
        default=24,
        metadata=_meta(
            "Side of the blocks of the first pass in pixels; each further pass uses blocks a "
            "third smaller, down to min_block. Larger blocks keep more of the texture's "
            "structure, smaller ones follow the target more closely.",
            ge=3,
            le=MAX_SIDE,
        ),
    )
    mode: TransferMode = field(
        default="cut",
        metadata=_meta(
            "'overlap': blocks joined with straight edges; 'cut': along the minimum-error "
            "boundary cut.",
            choices=TRANSFER_MODES,
        ),
    )
    alpha: float | None = field(
        default=None,
        metadata=_meta(
            "Weight of texture continuity against fidelity to the target: the cost is "
            "alpha x overlap error + (1 - alpha) x correspondence error, both per pixel. 1 "
            "ignores the target, 0 ignores the seams. None: 0.4 (i - 1) / (N - 1) + 0.1 at "
            "pass i of N, from 0.1 to 0.5 (0.5 for a single pass).",
            ge=0.0,
            le=1.0,
            optional=True,
        ),
    )
    iterations: int = field(
        default=2,
        metadata=_meta(
            "Number of passes N (the paper uses 3 to 5). Each pass after the first uses blocks "
            "a third smaller (down to min_block) and also matches what the previous pass put "
            "under the block.",
            ge=1,
            le=MAX_ITERATIONS,
        ),
    )
    min_block: int = field(
        default=16,
        metadata=_meta(
            "Smallest block of any pass in pixels: the passes stop shrinking there (a first "
            "block smaller than this is kept). Passes of blocks much smaller than the texture's "
            "features show as a lattice of small rectangles in flat areas and cost the most.",
            ge=3,
            le=MAX_SIDE,
        ),
    )
    correspondence: Correspondence = field(
        default="blurred",
        metadata=_meta(
            "What must correspond between the texture and the target: 'luminance', 'blurred' "
            "(Gaussian-blurred luminance), 'orientation' (local gradient orientation, compared "
            "as an angle) or 'custom' (maps given by the caller).",
            choices=CORRESPONDENCES,
        ),
    )
    remap: bool = field(
        default=True,
        metadata=_meta(
            "Shift the target's luminance map to the texture's mean brightness before "
            "comparing, so a target brighter or darker than the texture keeps its shapes "
            "instead of being matched by the texture's extremes. Applies to 'luminance' and "
            "'blurred'.",
            kind="bool",
        ),
    )
    shade: float = field(
        default=1.5,
        metadata=_meta(
            "Final shading: the output is brightened or darkened by at most this factor so "
            "that its luminance, at scales coarser than a third of the last pass's block, "
            "follows the target's (remapped) map; the texture's detail is kept, only scaled. "
            "1: off (every pixel a texture pixel). Applies to 'luminance' and 'blurred'.",
            ge=1.0,
            le=4.0,
        ),
    )
    sigma: float = field(
        default=2.0,
        metadata=_meta(
            "Gaussian sigma in pixels of the 'blurred' map, and the scale over which "
            "'orientation' averages gradients.",
            ge=0.1,
            le=64.0,
        ),
    )


@dataclass(frozen=True, kw_only=True)
class MatteOptions(QuiltOptions):
    """Parameters of texture matting (the alpha quilting and texture matting paper,
    §3): how the surface is read from the target
    (normals, light, clusters) and how each layer is quilted (the shared quilting options, and
    alpha quilting's for RGBA layers). Every layer is synthesized tileable, so ``walk`` is not
    offered.
    """

    mode: MatteMode = field(
        default="auto",
        metadata=_meta(
            "How each layer is quilted: 'auto' ('alpha' for an RGBA layer, else 'cut'), "
            "'random', 'overlap', 'cut' or 'alpha' (every layer then needs an alpha channel).",
            choices=MATTE_MODES,
        ),
    )
    histogram_weight: float = field(default=0.05, metadata=HISTOGRAM_WEIGHT)
    epsilon: float = field(default=0.02, metadata=EPSILON)
    eta: float = field(default=20.0, metadata=ETA)
    matting: MattingMethod = field(default="lkm", metadata=MATTING_META)
    clusters: int = field(
        default=8,
        metadata=_meta(
            "Number of k-means clusters of (nx, ny, nz, x, y) over the silhouette; each "
            "connected part of a cluster gets one texture patch, oriented by its mean normal. "
            "More clusters follow the surface more closely, with more patch borders.",
            ge=1,
            le=MAX_CLUSTERS,
        ),
    )
    light: tuple[float, float, float] | None = field(
        default=None,
        metadata=_meta(
            "Direction towards the light as [x, y, z] (x right, y up, z towards the viewer; "
            "any length, z > 0). None: estimated by least squares from the target's "
            "luminance and the surface normals.",
            kind="direction",
        ),
    )
    smoothing: float = field(
        default=2.0,
        metadata=_meta(
            "Gaussian sigma in pixels of the target's luminance before its gradients are "
            "taken (shape from shading), and of the estimated normals. 0: none.",
            ge=0.0,
            le=64.0,
        ),
    )
    min_z: float = field(
        default=0.1,
        metadata=_meta(
            "Smallest z component of a normal (the paper's 0.1); larger z values are kept, "
            "smaller ones raised to it and the normal renormalized, so no patch is stretched "
            "more than 1 / min_z.",
            ge=0.01,
            le=1.0,
        ),
    )
    spatial_weight: float = field(
        default=1.0,
        metadata=_meta(
            "Weight of the pixel position against the normal in the k-means features: "
            "positions are scaled to 0..spatial_weight across the silhouette's longer side. "
            "Larger gives compact patches, smaller groups by orientation alone.",
            ge=0.0,
            le=100.0,
        ),
    )
    scale: float = field(
        default=1.0,
        metadata=_meta(
            "Size of the texture on the surface: one texture pixel covers scale x scale "
            "target pixels where the surface faces the viewer. Each layer is quilted at the "
            "size of the silhouette's bounding box divided by scale (at least the block).",
            ge=0.25,
            le=64.0,
        ),
    )
    ambient: float = field(
        default=0.0,
        metadata=_meta(
            "Light that reaches every point: the shading is ambient + (1 - ambient) x "
            "max(n . S, 0). 0 is the paper's n . S; raise it to keep faces turned from the "
            "light from going black.",
            ge=0.0,
            le=1.0,
        ),
    )

    def __post_init__(self) -> None:
        if isinstance(self.light, list):  # JSON gives a list
            object.__setattr__(self, "light", tuple(self.light))
        super().__post_init__()
        if self.light is not None:
            object.__setattr__(self, "light", tuple(float(v) for v in self.light))


def _like(owner: type[_Declared], name: str, **changes: Any) -> Any:
    """A field declared as ``owner``'s field ``name`` (its documentation and limits), with
    ``changes`` (a default, say) put in: an option two classes share is documented once."""
    shared = next(f for f in fields(owner) if f.name == name)  # type: ignore[arg-type]
    return field(
        default=changes.pop("default", shared.default),
        metadata={**shared.metadata, **changes},
    )


FillBlend = Literal["none", "poisson"]
FILL_BLENDS: tuple[str, ...] = get_args(FillBlend)


@dataclass(frozen=True, kw_only=True)
class FillOptions(_Declared):
    """Parameters of filling a hole (:func:`quilting.fill`) and extending an image
    (:func:`quilting.extend`): blocks matched on every known pixel under them and joined to
    them along minimum cuts.

    Construction validates every field; an invalid value raises
    :class:`~quilting.core.errors.InvalidParameterError` naming the field and its range.
    Checks that need the image (a block larger than it, or than any part of it outside the
    hole) happen in ``fill``.
    """

    block: int = field(
        default=32,
        metadata=_meta(
            "Side of the square blocks in pixels. A candidate block is a whole block of the "
            "image outside the hole (or of the given texture), so the block must fit in the "
            "known part; a smaller block fits more places and follows a hole's outline more "
            "closely, a larger one keeps larger structures and fills faster.",
            ge=3,
            le=MAX_SIDE,
        ),
    )
    overlap: int | None = field(
        default=None,
        metadata=_meta(
            "How far neighbouring blocks of the fill overlap; None means block // 4 (at least "
            "1). Must be less than block / 2. Wider overlaps give the cuts more room.",
            ge=1,
            optional=True,
        ),
    )
    blend: FillBlend = field(
        default="poisson",
        metadata=_meta(
            "How a block's cut is joined: 'none', as the cut leaves it (every filled pixel a "
            "pixel of the source); 'poisson' (the default), the gradients across the cut "
            "replaced by the mean of both sides' and the block solved for them (screened "
            "Poisson, as synthesis blends its cells). Known pixels are never changed.",
            choices=FILL_BLENDS,
        ),
    )
    search_scale: int = field(
        default=0,
        metadata=_meta(
            "How the candidates are searched: 1, every block of the source scored at full "
            "size (exact, one full-size correlation per block); s > 1, first on the source and "
            "the block averaged over s x s cells (s² times cheaper), then at full size among "
            "the fine positions of the best coarse ones; 0 (the default), 1 for sources up to "
            "512x512 and block // 8 (1 to 4) above. Every backend chooses the same blocks "
            "either way.",
            ge=0,
            le=64,
        ),
    )
    tolerance: float = _like(QuiltOptions, "tolerance")
    min_candidates: int = _like(QuiltOptions, "min_candidates")
    error: ErrorKind = _like(QuiltOptions, "error")  # noqa: RUF009 (a field(), as above)
    seed: int = _like(QuiltOptions, "seed")
    backend: str = _like(QuiltOptions, "backend")

    def __post_init__(self) -> None:
        self._check_fields()
        _check_overlap(self.overlap, self.block)

    @property
    def resolved_overlap(self) -> int:
        """The overlap actually used: ``overlap`` or ``max(1, block // 4)``."""
        return self.overlap if self.overlap is not None else max(1, self.block // 4)


@dataclass(frozen=True, kw_only=True)
class ExtendOptions(FillOptions):
    """Parameters of extending an image past its borders (:func:`quilting.extend`): how many
    pixels to add on each side, and the fill's."""

    top: int = field(default=0, metadata=_meta("Rows added above the image.", ge=0, le=MAX_SIDE))
    bottom: int = field(default=0, metadata=_meta("Rows added below the image.", ge=0, le=MAX_SIDE))
    left: int = field(
        default=0, metadata=_meta("Columns added left of the image.", ge=0, le=MAX_SIDE)
    )
    right: int = field(
        default=0, metadata=_meta("Columns added right of the image.", ge=0, le=MAX_SIDE)
    )


TileMethod = Literal["cut", "fill"]
TILE_METHODS: tuple[str, ...] = get_args(TileMethod)


@dataclass(frozen=True, kw_only=True)
class TileOptions(_Declared):
    """Parameters of making an existing image tile (:func:`quilting.make_tileable`)."""

    axes: Tileable = field(
        default="both",
        metadata=_meta(
            "Which wraps must be seamless: 'both', 'x' (the last column joins the first) or "
            "'y' (the last row joins the first).",
            choices=TILEABLE,
        ),
    )
    band: int | None = field(
        default=None,
        metadata=_meta(
            "method='cut': width in pixels of each border band the cuts may wander in; None: a "
            "quarter of the side, so the middle half of the image is always kept. "
            "method='fill': width of the band re-synthesized across each wrap; None: a "
            "sixteenth of the side, at least 8. At most side / 2 - 1.",
            ge=1,
            optional=True,
        ),
    )
    blend: TileBlend = field(
        default="poisson",
        metadata=_meta(
            "How the four cuts are joined: 'none', as they are (every output pixel is an input "
            "pixel, bit for bit); 'poisson' (the default), the gradients across the cuts replaced"
            " by the mean of both sides' own and the whole image solved for them (Poisson, "
            "periodic along the tiled axes): a brightness gradient across the photo no longer "
            "shows as steps along the cuts, it is spread evenly over the period. Alpha is never "
            "blended. Companion maps: see Tiled.apply's kind.",
            choices=TILE_BLENDS,
        ),
    )
    method: TileMethod = field(
        default="cut",
        metadata=_meta(
            "How the wraps are made seamless: 'cut' (the default), the image kept inside four "
            "minimum-error cuts and the rest taken from itself rolled by half its size, so "
            "every pixel is an image pixel; 'fill', the image rolled by half its size and the "
            "band across each wrap (band pixels wide, default a sixteenth of the side, at "
            "least 8) synthesized again by quilting.fill from the rest of the image, as "
            "Embark's texture-synthesis makes an image tile. 'fill' re-synthesizes less of the "
            "image and leaves no long cut, but needs whole blocks of the image outside the "
            "bands.",
            choices=TILE_METHODS,
        ),
    )
    seed: int = _like(QuiltOptions, "seed")

    def __post_init__(self) -> None:
        self._check_fields()


def validate_size(size: Any) -> tuple[int, int]:
    """Check an output size given as ``(height, width)``.

    Returns
    -------
    tuple of int
        ``(height, width)``, each in 1..MAX_SIDE.
    """
    allowed = f"(height, width) with each side in 1..{MAX_SIDE}"
    try:
        height, width = size
    except (TypeError, ValueError):
        raise InvalidParameterError("size", size, allowed) from None
    for side in (height, width):
        if isinstance(side, bool) or not isinstance(side, int):
            raise InvalidParameterError("size", size, allowed, "sides must be integers")
        if not 1 <= side <= MAX_SIDE:
            raise InvalidParameterError("size", size, allowed)
    return int(height), int(width)


@dataclass(frozen=True, kw_only=True)
class WangOptions(_Declared):
    """Parameters of a Wang tile set (:func:`quilting.wang_tiles`): the set's colours and
    tile size, and the quilting of the texture its diamonds are cut from."""

    colors: int = field(
        default=2,
        metadata=_meta(
            "Colours per edge, C: the complete set has C^4 tiles (2: 16, 3: 81, 4: 256). More "
            "colours give more variety between neighbours and cost C^4 tiles.",
            ge=2,
            le=4,
        ),
    )
    tile: int = field(
        default=256,
        metadata=_meta(
            "Side of a tile in pixels, even. The diamonds of the edge colours are tile x tile "
            "squares of a texture quilted from the examples.",
            ge=16,
            le=4096,
            multiple_of=2,  # a tile is two diamond halves
        ),
    )
    block: int = _like(QuiltOptions, "block")
    overlap: int | None = _like(QuiltOptions, "overlap")
    blend: Blend = _like(  # noqa: RUF009 (a field(), as above)
        QuiltOptions,
        "blend",
        doc="How cuts are joined, in the quilted texture and along each tile's four cuts "
        "between its diamonds: 'none', as the cut leaves them; 'poisson' (the default), "
        "the step across each cut blended away by a screened Poisson solve (within a tile, "
        "its outline kept, so tiles still meet seamlessly).",
    )
    tolerance: float = _like(QuiltOptions, "tolerance")
    min_candidates: int = _like(QuiltOptions, "min_candidates")
    error: ErrorKind = _like(QuiltOptions, "error")  # noqa: RUF009 (a field(), as above)
    continuation: Continuation = field(default="auto", metadata=CONTINUATION_META)
    transforms: str = field(default="none", metadata=TRANSFORMS_META)
    weights: tuple[float, ...] | None = field(default=None, metadata=WEIGHTS_META)
    seed: int = _like(QuiltOptions, "seed")
    backend: str = _like(QuiltOptions, "backend")

    def __post_init__(self) -> None:
        object.__setattr__(self, "transforms", canonical_transforms(self.transforms))
        object.__setattr__(self, "weights", example_weights(self.weights))
        self._check_fields()
        _check_overlap(self.overlap, self.block)

    def synthesis(self) -> SynthesisOptions:
        """The options of the quilting of the diamonds' texture."""
        shared = {f.name for f in fields(SynthesisOptions)} & {f.name for f in fields(self)}
        return SynthesisOptions(**{name: getattr(self, name) for name in shared})


@dataclass(frozen=True, kw_only=True)
class AlphaOptions(_Declared):
    """Parameters of extracting an alpha from a photo and a trimap or scribbles
    (:func:`quilting.extract_alpha`)."""

    method: MattingMethod = field(default="lkm", metadata=MATTING_META)
    foreground: ForegroundKind = field(
        default="ml",
        metadata=_meta(
            "The RGBA texture's colour: 'ml', the foreground estimated under the alpha "
            "(multi-level foreground estimation, Germer et al. 2020), so that the background "
            "seen through semi-transparent pixels does not stay in the texture; 'photo', the "
            "photo's own colours (the background's tint stays at the edges).",
            choices=FOREGROUND_KINDS,
        ),
    )

    def __post_init__(self) -> None:
        self._check_fields()
