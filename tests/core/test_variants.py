"""Error and discard options: luminance error, random discarding of candidates."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from textures import assert_same_as_reference, backends

import quilting
from quilting import InvalidParameterError
from quilting.core.fields import Shortlist
from quilting.core.pixels import luminance, to_working
from quilting.core.select import discard_depth, enough_survive, survivors


@pytest.fixture(scope="module")
def colour(hubble: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(hubble[:96, :96])


def _bytes(texture: np.ndarray, **options: Any) -> bytes:
    result = quilting.synthesize(texture, (90, 90), block=16, seed=3, **options)
    return result.image.tobytes()


@pytest.mark.parametrize("options", [{"error": "luminance"}, {"discard": 0.5}])
def test_options_change_the_result_deterministically(colour, options) -> None:
    first, again = _bytes(colour, **options), _bytes(colour, **options)
    assert first == again
    assert first != _bytes(colour)


def test_luminance_error_on_gray_is_the_rgb_error(gravel) -> None:
    texture = gravel[:96, :96]
    assert _bytes(texture, error="luminance") == _bytes(texture)


def test_discard_zero_is_no_discard(colour) -> None:
    assert _bytes(colour, discard=0.0) == _bytes(colour)


def _first_pair_choice(texture: np.ndarray, **options: Any) -> tuple[np.ndarray, Any]:
    """The second block of the first row: its only overlap is the first block's right edge."""
    result = quilting.synthesize(
        texture, (40, 40), block=16, overlap=4, seed=11, backend="reference", **options
    )
    return to_working(result.image), result.layout.passes[0]


def _first_strip(texture: np.ndarray, layout: Any) -> np.ndarray:
    """The first block's right strip (16 x 4, working pixels): what the second block was
    matched against (the output there is the second block's where its cut gives it)."""
    y, x = (int(v) for v in layout.positions[0, 0])
    return to_working(texture)[y : y + 16, x + 12 : x + 16]


def _left_errors(match: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Brute force: the overlap error of every candidate against the left strip."""
    windows = np.lib.stride_tricks.sliding_window_view(match, (16, 4), axis=(0, 1))
    strips = windows.transpose(0, 1, 3, 4, 2)  # (fy, fx, 16, 4, C)
    return ((strips - template) ** 2).sum(axis=(2, 3, 4))[:, : match.shape[1] - 15]


def test_luminance_error_chooses_by_luminance(colour) -> None:
    """The block chosen passes the tolerance rule measured on luminance (from the 3rd best)."""
    _, layout = _first_pair_choice(colour, error="luminance")
    match = luminance(to_working(colour))[..., None]
    errors = _left_errors(match, luminance(_first_strip(colour, layout))[..., None])
    y, x = layout.positions[0, 1]
    assert errors[y, x] <= 1.1 * np.sort(errors.ravel())[2] + 1e-12


def test_discarding_follows_the_rule_over_the_survivors(colour) -> None:
    """The block chosen is acceptable among the candidates that survived: the best
    candidates may be gone, and then a worse one is chosen."""
    _, plain = _first_pair_choice(colour, min_candidates=1)
    _, layout = _first_pair_choice(colour, min_candidates=1, discard=0.9)
    source = to_working(colour)
    errors = _left_errors(source, _first_strip(colour, layout)).ravel()
    field_width = colour.shape[1] - 15
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([11, 0, 0, 1])))
    key = int(rng.integers(0, 2**64, dtype=np.uint64))
    kept = survivors(key, np.arange(errors.size), 0.9)
    y, x = layout.positions[0, 1]
    chosen = y * field_width + x
    assert kept[chosen]
    assert errors[chosen] <= 1.1 * errors[kept].min() + 1e-12
    assert errors[chosen] > errors.min()  # the overall best was discarded
    assert tuple(layout.positions[0, 1]) != tuple(plain.positions[0, 1])


def test_discarding_breaks_verbatim_copies(brick) -> None:
    """With the paper's bare rule (min_candidates=1) the best match next to a copied block
    is its own continuation; discarding it breaks the copy."""
    copies = {
        p: quilting.synthesize(
            brick, (300, 300), block=40, seed=1, min_candidates=1, discard=p
        ).stats.largest_copy
        for p in (0.0, 0.5, 0.9)
    }
    assert copies[0.9] < copies[0.5] < copies[0.0]


@pytest.mark.parametrize("options", [{"error": "luminance"}, {"discard": 0.7}])
@pytest.mark.parametrize("with_gl", [False, pytest.param(True, marks=pytest.mark.gl)])
def test_backends_agree(request, colour, options, with_gl) -> None:
    texture = colour[:48, :48]
    images = {
        name: quilting.synthesize(
            texture, (40, 40), block=10, seed=5, backend=backend, **options
        ).image
        for name, backend in backends(request, with_gl).items()
    }
    assert_same_as_reference(images)


def test_transfer_takes_both_options(colour) -> None:
    target = np.ascontiguousarray(colour[::-1, ::-1, 0])
    kwargs: dict[str, Any] = {"block": 12, "iterations": 2, "seed": 2}
    plain = quilting.transfer(colour, target, **kwargs).image
    for options in ({"error": "luminance"}, {"discard": 0.5}):
        first = quilting.transfer(colour, target, **kwargs, **options).image
        again = quilting.transfer(colour, target, **kwargs, **options).image
        assert np.array_equal(first, again)
        assert not np.array_equal(first, plain)


def test_survivors_are_a_fair_deterministic_coin() -> None:
    index = np.arange(200_000)
    kept = survivors(12345, index, 0.3)
    assert kept.mean() == pytest.approx(0.7, abs=0.005)
    assert np.array_equal(kept, survivors(12345, index, 0.3))
    assert not np.array_equal(kept, survivors(12346, index, 0.3))
    # One candidate's fate does not depend on what else is asked about.
    assert np.array_equal(survivors(12345, index[::7], 0.3), kept[::7])


def test_enough_survive_needs_k_among_the_depth_best() -> None:
    listed = Shortlist(np.arange(6), np.array([5.0, 1.0, 2.0, 3.0, 4.0, 0.5]), 0.0)
    kept = np.array([True, False, True, True, True, False])
    assert not enough_survive(listed, kept, depth=3, k=2, field_size=100)  # best: 5, 1, 2
    assert enough_survive(listed, kept, depth=4, k=2, field_size=100)
    assert enough_survive(listed, kept, depth=3, k=2, field_size=3)  # the list is the field
    assert discard_depth(3, 0.0) >= 3 and discard_depth(3, 0.9) > 30


@pytest.mark.parametrize(
    "options,parameter",
    [({"error": "lab"}, "error"), ({"discard": 1.0}, "discard"), ({"discard": -0.1}, "discard")],
)
def test_bad_values_are_named(gravel, options, parameter) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        quilting.synthesize(gravel, (50, 50), **options)
    assert caught.value.parameter == parameter
