"""``quilting.api.check_inputs`` refuses exactly what the engine refuses.

The HTTP service calls :func:`quilting.api.check_inputs` before it queues a job, so the check
must agree with :func:`quilting.synthesize`, :func:`quilting.transfer` and
:func:`quilting.wang_tiles` given the same inputs: a job it accepts that the engine then
refuses fails after it was queued, and a job it refuses that the engine would run is refused
wrongly. Over a hand-made matrix of small cases (textures 8x8 to 64x64; gray, RGB and RGBA;
uint8, uint16, float32 and float64; outputs at most 96x96, a fixed seed and the ``fft``
backend, so each engine call takes a few milliseconds), each case declares what the engine
must do (run, or raise which :class:`quilting.QuiltingError` subclass) and these tests check:

* the engine does that, and raises nothing but a ``QuiltingError`` (a ``ValueError`` from
  deep inside is a bug, reported with its traceback);
* ``check_inputs`` raises a ``QuiltingError`` of the same class exactly when the engine does;
* ``check_inputs`` raises nothing but ``QuiltingError`` subclasses.

A Wang job is checked as the service checks it: with the size of the material its tiles are
cut from, a tile high and two colours' diamonds of a tile each wide.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeAlias

import numpy as np
import pytest
from numpy.typing import NDArray

import quilting
from quilting import InvalidImageError, InvalidParameterError, QuiltingError
from quilting.api import check_inputs
from quilting.options import SynthesisOptions, TransferOptions, WangOptions

Options: TypeAlias = SynthesisOptions | TransferOptions | WangOptions
#: What the engine does with a case: run (None), or raise exactly this class.
Expected: TypeAlias = type[QuiltingError] | None

#: Every job's seed and backend: the same blocks on every machine, whatever 'auto' would pick.
FIXED: dict[str, Any] = {"seed": 7, "backend": "fft"}


def noise(
    height: int, width: int, channels: int = 0, dtype: str = "uint8", seed: int = 0
) -> NDArray[Any]:
    """A random texture, (height, width) or (height, width, channels); uint8 values stay
    below 200 and float values below 1, so the exclusions below never catch one of its pixels."""
    rng = np.random.default_rng(seed)
    shape = (height, width) if channels == 0 else (height, width, channels)
    if dtype == "uint8":
        return rng.integers(0, 200, shape, dtype=np.uint8)
    if dtype == "uint16":
        return rng.integers(0, 200 * 257, shape, dtype=np.uint16)
    return rng.random(shape).astype(dtype)


def framed(
    texture: NDArray[Any], window: tuple[int, int, int, int], colour: float | tuple[float, ...]
) -> NDArray[Any]:
    """``texture`` painted ``colour`` everywhere outside ``window`` (top, left, height, width)."""
    top, left, height, width = window
    painted = np.empty_like(texture)
    painted[...] = colour
    painted[top : top + height, left : left + width] = texture[
        top : top + height, left : left + width
    ]
    return painted


def mask(shape: tuple[int, int], window: tuple[int, int, int, int]) -> NDArray[np.uint8]:
    """A source mask of ``shape``: white inside ``window`` (top, left, height, width), black
    (never used) everywhere else."""
    top, left, height, width = window
    marks = np.zeros(shape, dtype=np.uint8)
    marks[top : top + height, left : left + width] = 255
    return marks


@dataclass(frozen=True)
class Case:
    """One job: its options, texture (or examples), source mask and output size, and what the
    engine must do with it."""

    name: str
    options: Options
    texture: Any
    expected: Expected
    source_mask: Any = None
    #: The synthesis's output, or the transfer's target; a Wang job's is its material's.
    size: tuple[int, int] = field(default=(48, 48))


def synth(name: str, texture: Any, expected: Expected, **given: Any) -> Case:
    """A synthesis case: ``source_mask`` and ``size`` from ``given``, the rest options."""
    mask_given, size = given.pop("source_mask", None), given.pop("size", (48, 48))
    options = SynthesisOptions(**FIXED, **given)
    return Case("synthesize/" + name, options, texture, expected, mask_given, size)


def transfer(name: str, texture: Any, expected: Expected, **given: Any) -> Case:
    """A transfer case onto a 48x48 gray target; ``source_mask`` from ``given``."""
    mask_given = given.pop("source_mask", None)
    return Case(
        "transfer/" + name, TransferOptions(**FIXED, **given), texture, expected, mask_given
    )


def wang(name: str, texture: Any, expected: Expected, **given: Any) -> Case:
    """A Wang tile case (16-pixel tiles unless ``given`` says otherwise)."""
    options = WangOptions(**{"tile": 16, **FIXED, **given})
    material = (options.tile, 2 * options.colors * options.tile)
    return Case("wang/" + name, options, texture, expected, None, material)


IMAGE, PARAMETER = InvalidImageError, InvalidParameterError
GRAY = noise(32, 32)
WHITE = (255, 255, 255)
EXCLUDE_WHITE_GRAY = [[[250], [255]]]
EXCLUDE_WHITE_RGB = [[[250, 250, 250], [255, 255, 255]]]
#: Finite floats whose squares overflow float32: every cost over them is inf or NaN.
HUGE32 = noise(16, 16, dtype="float32") * np.float32(1e30)
HUGE_RGBA32 = noise(16, 16, 4, dtype="float32") * np.float32(1e30)
#: Finite as float64, inf once the engine works in float32.
HUGE64 = noise(16, 16, dtype="float64") * 1e300

SYNTHESIS = [
    # Accepted: every kind of texture the engine takes.
    synth("gray-uint8-32x32", GRAY, None, block=16),
    synth("rgb-uint8-64x64-to-96x96", noise(64, 64, 3), None, block=24, size=(96, 96)),
    synth("rgba-uint8-auto-is-alpha", noise(32, 32, 4), None, block=12),
    synth("rgb-float32", noise(32, 32, 3, "float32"), None, block=16),
    synth("rgba-float32", noise(24, 24, 4, "float32"), None, block=12),
    synth("gray-uint16", noise(32, 32, dtype="uint16"), None, block=16),
    synth("gray-float64", noise(16, 16, dtype="float64"), None, block=8),
    # The block against the texture's sides.
    synth("8x8-block-8", noise(8, 8, 3), None, block=8, size=(20, 20)),
    synth("8x8-block-9", noise(8, 8, 3), PARAMETER, block=9, size=(20, 20)),
    synth("block-taller-than-texture", noise(32, 40), PARAMETER, block=36),
    synth("block-wider-than-texture", noise(40, 32), PARAMETER, block=36),
    synth("block-equals-both-sides", GRAY, None, block=32),
    synth("block-equals-shorter-side", noise(24, 40), None, block=24),
    synth("block-equals-shorter-width", noise(40, 24, 3), None, block=24),
    # Tileable sides against the block.
    synth("tileable-x-width-under-block", GRAY, PARAMETER, block=16, tileable="x", size=(48, 12)),
    synth("tileable-y-height-under-block", GRAY, PARAMETER, block=16, tileable="y", size=(12, 48)),
    synth(
        "tileable-both-one-side-short", GRAY, PARAMETER, block=16, tileable="both", size=(48, 15)
    ),
    synth("tileable-both-sides-equal-block", GRAY, None, block=16, tileable="both", size=(16, 16)),
    synth("tileable-x-plane-axis-short", GRAY, None, block=16, tileable="x", size=(12, 48)),
    synth("tileable-y-plane-axis-short", GRAY, None, block=16, tileable="y", size=(48, 12)),
    # Alpha mode needs an alpha channel.
    synth("alpha-mode-gray", GRAY, PARAMETER, block=16, mode="alpha"),
    synth("alpha-mode-rgb", noise(32, 32, 3), PARAMETER, block=16, mode="alpha"),
    synth("alpha-mode-float32-rgb", noise(32, 32, 3, "float32"), PARAMETER, block=16, mode="alpha"),
    synth("alpha-mode-rgba", noise(32, 32, 4), None, block=16, mode="alpha"),
    synth("walk-mode-rgba", noise(32, 32, 4), None, block=16, mode="walk"),
    # A source mask leaving exactly one whole block, or none.
    synth(
        "mask-leaves-one-block", GRAY, None, block=16, source_mask=mask((32, 32), (5, 7, 16, 16))
    ),
    synth(
        "mask-leaves-no-block",
        GRAY,
        PARAMETER,
        block=16,
        source_mask=mask((32, 32), (5, 7, 15, 16)),
    ),
    synth(
        "mask-leaves-one-block-walk",
        GRAY,
        None,
        block=16,
        mode="walk",
        source_mask=mask((32, 32), (16, 16, 16, 16)),
    ),
    synth(
        "mask-leaves-one-block-random",
        GRAY,
        None,
        block=16,
        mode="random",
        source_mask=mask((32, 32), (0, 0, 16, 16)),
    ),
    synth(
        "mask-leaves-one-block-tileable",
        GRAY,
        None,
        block=16,
        tileable="both",
        source_mask=mask((32, 32), (5, 7, 16, 16)),
    ),
    synth(
        "mask-rgb-leaves-one-block-alpha",
        noise(32, 32, 4),
        None,
        block=16,
        source_mask=np.dstack([mask((32, 32), (9, 3, 16, 16))] * 3),
    ),
    synth("mask-wrong-size", GRAY, IMAGE, block=16, source_mask=np.full((30, 32), 255, np.uint8)),
    synth("mask-one-dimensional", GRAY, IMAGE, block=16, source_mask=np.full(32, 255, np.uint8)),
    synth(
        "mask-list-for-one-texture", GRAY, IMAGE, block=16, source_mask=[mask((32, 32), (0,) * 4)]
    ),
    # Excluded colours leaving exactly one whole block, or none.
    synth(
        "exclude-gray-leaves-one-block",
        framed(GRAY, (3, 9, 16, 16), 255),
        None,
        block=16,
        exclude_colors=EXCLUDE_WHITE_GRAY,
    ),
    synth(
        "exclude-gray-leaves-no-block",
        framed(GRAY, (3, 9, 16, 15), 255),
        PARAMETER,
        block=16,
        exclude_colors=EXCLUDE_WHITE_GRAY,
    ),
    synth(
        "exclude-rgb-leaves-one-block",
        framed(noise(32, 32, 3), (10, 0, 16, 16), WHITE),
        None,
        block=16,
        exclude_colors=EXCLUDE_WHITE_RGB,
    ),
    synth(
        "exclude-rgb-leaves-no-block",
        framed(noise(32, 32, 3), (10, 0, 15, 32), WHITE),
        PARAMETER,
        block=16,
        exclude_colors=EXCLUDE_WHITE_RGB,
    ),
    synth(
        "exclude-rgba-colour-leaves-one-block-walk",
        framed(noise(32, 32, 4), (0, 16, 16, 16), (*WHITE, 128)),
        None,
        block=16,
        mode="walk",
        exclude_colors=EXCLUDE_WHITE_RGB,
    ),
    synth(
        "exclude-float32-leaves-no-block",
        framed(noise(32, 32, dtype="float32"), (0, 0, 15, 15), 1.0),
        PARAMETER,
        block=16,
        exclude_colors=[[[0.9], [1.0]]],
    ),
    synth(
        "exclude-and-mask-together-leave-one-block",
        framed(GRAY, (4, 4, 16, 20), 255),
        None,
        block=16,
        exclude_colors=EXCLUDE_WHITE_GRAY,
        source_mask=mask((32, 32), (0, 8, 32, 24)),
    ),
    synth(
        "exclude-and-mask-together-leave-no-block",
        framed(GRAY, (4, 4, 16, 20), 255),
        PARAMETER,
        block=16,
        exclude_colors=EXCLUDE_WHITE_GRAY,
        source_mask=mask((32, 32), (0, 9, 32, 23)),
    ),
    synth("exclude-three-values-for-gray", GRAY, PARAMETER, block=16, exclude_colors=[[WHITE] * 2]),
    synth(
        "exclude-one-value-for-rgb",
        noise(32, 32, 3),
        PARAMETER,
        block=16,
        exclude_colors=[[[1], [2]]],
    ),
    # Several examples.
    synth("examples-two-sizes", [GRAY, noise(24, 40, seed=1)], None, block=16),
    synth("examples-gray-and-rgb", [GRAY, noise(32, 32, 3)], IMAGE, block=16),
    synth("examples-rgb-and-rgba", [noise(32, 32, 3), noise(32, 32, 4)], IMAGE, block=16),
    synth("examples-uint8-and-float32", [GRAY, noise(32, 32, dtype="float32")], IMAGE, block=16),
    synth("examples-one-shorter-than-block", [GRAY, noise(12, 40)], PARAMETER, block=16),
    synth("examples-weights-one-each", [GRAY, noise(24, 40)], None, block=16, weights=(1, 3)),
    synth(
        "examples-weights-too-many", [GRAY, noise(24, 40)], PARAMETER, block=16, weights=(1, 2, 3)
    ),
    synth("examples-weights-too-few", [GRAY, noise(24, 40)], PARAMETER, block=16, weights=(2,)),
    synth("one-texture-two-weights", GRAY, PARAMETER, block=16, weights=(1, 2)),
    synth(
        "examples-masks-leave-one-block-in-second",
        [GRAY, noise(32, 32, seed=2)],
        None,
        block=16,
        source_mask=[mask((32, 32), (0, 0, 15, 32)), mask((32, 32), (16, 16, 16, 16))],
    ),
    synth(
        "examples-masks-leave-no-block",
        [GRAY, noise(32, 32, seed=2)],
        PARAMETER,
        block=16,
        source_mask=[mask((32, 32), (0, 0, 15, 32)), mask((32, 32), (16, 16, 16, 15))],
    ),
    synth(
        "examples-mask-list-too-short",
        [GRAY, GRAY],
        IMAGE,
        block=16,
        source_mask=[mask((32, 32), (0, 0, 16, 16))],
    ),
    synth(
        "examples-one-mask-array-for-two",
        [GRAY, GRAY],
        IMAGE,
        block=16,
        source_mask=mask((32, 32), (0, 0, 16, 16)),
    ),
    synth("transforms-all-non-square", noise(20, 40), None, block=16, transforms="all"),
    synth(
        "transforms-mask-leaves-one-block",
        GRAY,
        None,
        block=16,
        transforms="rotations",
        source_mask=mask((32, 32), (5, 7, 16, 16)),
    ),
    synth(
        "walk-transforms-examples",
        [noise(16, 24), noise(20, 16, seed=3)],
        None,
        block=16,
        mode="walk",
        transforms="flips",
        size=(40, 40),
    ),
    # Not a texture at all.
    synth("no-examples", [], IMAGE, block=16),
    synth("two-channels", noise(32, 32, 2), IMAGE, block=16),
    synth("float32-nan", np.full((32, 32), np.nan, np.float32), IMAGE, block=16),
    synth("nested-python-list", [[1, 2, 3]] * 3, IMAGE, block=3),
    synth("output-side-zero", GRAY, PARAMETER, block=16, size=(0, 48)),
    # Finite floats the engine cannot compute with (its costs overflow float32): refused as an
    # image it cannot take, never a ValueError from numpy halfway through the job.
    synth("float32-huge-cut", HUGE32, IMAGE, block=8, size=(24, 24)),
    synth("float32-huge-walk", HUGE32, IMAGE, block=8, mode="walk", size=(24, 24)),
    synth("float32-rgba-huge-alpha", HUGE_RGBA32, IMAGE, block=8, size=(24, 24)),
    synth("float64-overflows-float32", HUGE64, IMAGE, block=8, size=(24, 24)),
]
TRANSFER = [
    transfer("gray-uint8", GRAY, None, block=12),
    transfer("rgba-uint8", noise(32, 32, 4), None, block=12),
    transfer("rgb-float32", noise(32, 32, 3, "float32"), None, block=12),
    transfer("block-taller-than-texture", noise(32, 40), PARAMETER, block=36),
    transfer("block-wider-than-texture", noise(40, 32), PARAMETER, block=36),
    transfer("block-equals-texture-side", GRAY, None, block=32, min_block=16),
    transfer("list-of-textures", [GRAY, GRAY], IMAGE, block=12),
    transfer("list-of-one-texture", [GRAY], IMAGE, block=12),
    transfer("mask-list", GRAY, IMAGE, block=12, source_mask=[mask((32, 32), (0, 0, 16, 16))]),
    transfer(
        "mask-leaves-one-block", GRAY, None, block=12, source_mask=mask((32, 32), (3, 5, 12, 12))
    ),
    transfer(
        "mask-leaves-no-block",
        GRAY,
        PARAMETER,
        block=12,
        source_mask=mask((32, 32), (3, 5, 11, 12)),
    ),
    transfer(
        "mask-leaves-one-first-block-of-three-passes",
        GRAY,
        None,
        block=24,
        iterations=3,
        min_block=6,
        source_mask=mask((32, 32), (8, 2, 24, 24)),
    ),
    transfer("mask-wrong-size", GRAY, IMAGE, block=12, source_mask=np.full((32, 30), 9, np.uint8)),
    transfer(
        "exclude-leaves-one-block",
        framed(GRAY, (3, 9, 16, 16), 255),
        None,
        block=16,
        exclude_colors=EXCLUDE_WHITE_GRAY,
    ),
    transfer(
        "exclude-leaves-no-block",
        framed(GRAY, (3, 9, 15, 16), 255),
        PARAMETER,
        block=16,
        exclude_colors=EXCLUDE_WHITE_GRAY,
    ),
    transfer(
        "exclude-three-values-for-gray", GRAY, PARAMETER, block=12, exclude_colors=[[WHITE] * 2]
    ),
    transfer("float32-nan", np.full((32, 32), np.nan, np.float32), IMAGE, block=12),
    transfer("float32-huge", HUGE32, IMAGE, block=8),
]

WANG = [
    wang("gray-uint8", GRAY, None, block=12),
    wang("rgba-uint8-auto-is-alpha", noise(32, 32, 4), None, block=12),
    wang("rgb-float32", noise(32, 32, 3, "float32"), None, block=12),
    wang("three-colours", GRAY, None, block=12, colors=3),
    wang("block-larger-than-texture", GRAY, PARAMETER, block=36),
    wang("block-equals-texture-side", noise(16, 24), None, block=16),
    wang("block-larger-than-tile", GRAY, None, block=24),
    wang("examples-gray-and-rgb", [GRAY, noise(32, 32, 3)], IMAGE, block=12),
    wang("examples-one-shorter-than-block", [GRAY, noise(32, 10)], PARAMETER, block=12),
    wang("examples-weights-one-each", [GRAY, noise(20, 20)], None, block=12, weights=(1, 2)),
    wang("examples-weights-too-many", [GRAY, GRAY], PARAMETER, block=12, weights=(1, 2, 3)),
    wang("transforms-all-non-square", noise(16, 24), None, block=12, transforms="all"),
    wang("float32-nan", np.full((32, 32), np.nan, np.float32), IMAGE, block=12),
    wang("float32-huge", HUGE32, IMAGE, block=8),
]

CASES = SYNTHESIS + TRANSFER + WANG
each_case = pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
TARGET = noise(48, 48, seed=9)


def engine(case: Case) -> None:
    """Run the case's job through the public function the service's worker calls."""
    options = case.options
    if isinstance(options, WangOptions):
        quilting.wang_tiles(case.texture, options)
    elif isinstance(options, TransferOptions):
        target = TARGET[: case.size[0], : case.size[1]]
        quilting.transfer(case.texture, target, options, source_mask=case.source_mask)
    else:
        quilting.synthesize(case.texture, case.size, options, source_mask=case.source_mask)


def precheck(case: Case) -> None:
    """Check the case's job as the service does before queueing it."""
    check_inputs(case.options, case.texture, case.source_mask, case.size)


def refusal(call: Callable[[Case], None], case: Case) -> QuiltingError | None:
    """The QuiltingError ``call`` raises on ``case``, or None when it runs; any other
    exception propagates, failing the test with its traceback."""
    try:
        call(case)
    except QuiltingError as exc:
        return exc
    return None


def described(refused: QuiltingError | None) -> str:
    return "accepted" if refused is None else f"{type(refused).__name__}: {refused}"


def kind(refused: QuiltingError | None) -> Expected:
    return None if refused is None else type(refused)


def test_the_matrix_holds_accepted_and_refused_jobs_of_each_function() -> None:
    for group in (SYNTHESIS, TRANSFER, WANG):
        outcomes = {case.expected for case in group}
        assert None in outcomes
        assert {IMAGE, PARAMETER} <= outcomes


@each_case
def test_the_engine_refuses_exactly_the_bad_jobs(case: Case) -> None:
    refused = refusal(engine, case)
    assert kind(refused) is case.expected, (
        f"expected {case.expected.__name__ if case.expected else 'accepted'}, "
        f"engine: {described(refused)}"
    )


@each_case
def test_check_inputs_refuses_what_the_engine_refuses(case: Case) -> None:
    by_engine = refusal(engine, case)
    by_check = refusal(precheck, case)
    assert kind(by_check) is kind(by_engine), (
        f"check_inputs: {described(by_check)}; engine: {described(by_engine)}"
    )


@each_case
def test_check_inputs_raises_nothing_but_quilting_errors(case: Case) -> None:
    try:
        precheck(case)
    except QuiltingError:
        pass
    except Exception as exc:  # any other exception is the failure itself
        pytest.fail(f"check_inputs raised {type(exc).__name__}: {exc}, not a QuiltingError")
