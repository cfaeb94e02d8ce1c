"""Several examples and their rotations and mirrors as sources (issue 25,
:mod:`quilting.core.sources`): the atlas, the candidate field over it, weights, layouts of
several examples, and normal maps turned with their pixels."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from tests.core.textures import backends, texture

import quilting
from quilting.core.errors import InvalidImageError, InvalidParameterError, LayoutError
from quilting.core.exclusion import allowed_candidates
from quilting.core.sources import (
    PRESETS,
    SWAPPING,
    TRANSFORMS,
    SourceSet,
    transform_names,
    transformed,
    turn_normals,
)
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend

BLOCK = 12


def crop(name: str, top: int, left: int, height: int, width: int) -> NDArray[Any]:
    return np.ascontiguousarray(texture(name)[top : top + height, left : left + width])


def examples() -> list[NDArray[Any]]:
    """Three examples of one texture, of three sizes."""
    return [
        crop("gravel", 0, 0, 40, 40),
        crop("gravel", 50, 20, 36, 52),
        crop("gravel", 90, 60, 44, 30),
    ]


# --- transforms ---------------------------------------------------------------------------


def test_transform_names_normalize_presets_lists_and_text() -> None:
    assert transform_names("none") == ("identity",)
    assert transform_names("all") == TRANSFORMS
    assert transform_names("rotations") == PRESETS["rotations"]
    assert transform_names("flip_x, rot90") == ("identity", "rot90", "flip_x")
    assert transform_names(["transverse", "identity"]) == ("identity", "transverse")
    assert transform_names("flips,rot90") == ("identity", "rot90", "rot180", "flip_x", "flip_y")
    for bad in ("spin", ["rot45"], 3, "rot90,,twist"):
        with pytest.raises(InvalidParameterError, match="transforms"):
            transform_names(bad)
    options = quilting.SynthesisOptions(transforms=["rot180", "rot90", "rot270"])
    assert options.transforms == "rotations"  # stored in one canonical form
    assert quilting.SynthesisOptions(transforms="flip_y").transforms == "identity,flip_y"


def test_the_transforms_are_the_eight_symmetries_of_the_square() -> None:
    image = np.arange(5 * 7).reshape(5, 7)
    seen = {
        transformed(image, name).tobytes() + bytes(transformed(image, name).shape)
        for name in TRANSFORMS
    }
    assert len(seen) == 8
    assert np.array_equal(transformed(image, "rot90"), np.rot90(image))
    assert np.array_equal(transformed(transformed(image, "transpose"), "transpose"), image)
    assert np.array_equal(transformed(image, "transverse"), np.rot90(image, 2).T)


def heights(size: int = 24) -> NDArray[np.float64]:
    """A smooth, asymmetric height field."""
    y, x = np.mgrid[0:size, 0:size] / size
    return np.sin(3 * x + 1.3 * y**2) + 0.5 * np.cos(5 * y - 2 * x * y)


def normal_map(h: NDArray[np.float64], y_sign: int) -> NDArray[np.float64]:
    """A tangent-space normal map of ``h``, stored as (n + 1) / 2: x to the right, y up
    (``y_sign`` -1, OpenGL) or down (1, DirectX)."""
    dy, dx = np.gradient(h)  # along rows (down) and columns (right)
    # The normal's in-plane part is minus the gradient; the map's y is y_sign times the rows'.
    n = np.stack([-dx, -y_sign * dy, np.ones_like(h)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return (n + 1) / 2


@pytest.mark.parametrize("y_sign", [-1, 1])
@pytest.mark.parametrize("name", TRANSFORMS)
def test_a_turned_normal_map_is_the_normal_map_of_the_turned_surface(
    name: str, y_sign: int
) -> None:
    """Turning a surface and computing its normals gives the normals turned with their pixels
    (x and y swapped and negated as the transform moves the axes) in either convention."""
    h = heights()
    turned = turn_normals(normal_map(h, y_sign), name, y_sign)
    expected = normal_map(np.ascontiguousarray(transformed(h, name)), y_sign)
    assert np.allclose(turned, expected, atol=1e-12)
    if name in SWAPPING:
        # Read in the other convention, a transform that swaps the axes turns the vectors
        # the wrong way round (the mirrors and the half turn are the same in both).
        wrong = turn_normals(normal_map(h, y_sign), name, -y_sign)
        assert not np.allclose(wrong, expected, atol=1e-3)


def test_turning_8_bit_normals_is_exact() -> None:
    stored = (normal_map(heights(), -1) * 255).round().astype(np.uint8)
    turned = turn_normals(stored, "rot90")
    assert turned.dtype == np.uint8
    # rot90 (counter-clockwise), green up: the new x is the old -y, the new y the old x.
    moved = np.rot90(stored)
    assert np.array_equal(turned[..., 0], 255 - moved[..., 1])
    assert np.array_equal(turned[..., 1], moved[..., 0])
    assert np.array_equal(turned[..., 2], moved[..., 2])


# --- the atlas ----------------------------------------------------------------------------


@pytest.mark.parametrize("transforms", ["none", "flips", "all"])
@pytest.mark.parametrize("margin", [1, BLOCK])
def test_no_candidate_straddles_two_placements_and_none_inside_is_lost(
    transforms: str, margin: int
) -> None:
    shapes = [(40, 40), (36, 52), (44, 30)]
    plan = SourceSet.plan(shapes, transform_names(transforms), margin)
    allowed = allowed_candidates(plan.excluded(), BLOCK).reshape(
        plan.shape[0] - BLOCK + 1, plan.shape[1] - BLOCK + 1
    )
    inside = np.zeros_like(allowed)
    for p in plan.placements:
        assert p.y >= margin and p.x >= margin
        assert p.y + p.height + margin <= plan.shape[0] and p.x + p.width + margin <= plan.shape[1]
        h, w = shapes[p.example]
        assert (p.height, p.width) == ((w, h) if p.transform in SWAPPING else (h, w))
        window = inside[p.y : p.y + p.height - BLOCK + 1, p.x : p.x + p.width - BLOCK + 1]
        assert not window.any(), "placements overlap"
        window[...] = True
    assert np.array_equal(allowed, inside)
    assert len(plan.placements) == len(shapes) * len(transform_names(transforms))


def test_the_atlas_holds_each_transformed_example_and_locates_positions() -> None:
    views = [e[..., None] if e.ndim == 2 else e for e in examples()]
    plan = SourceSet.plan([v.shape[:2] for v in views], TRANSFORMS, 1)
    atlas = plan.build(views)
    for index, p in enumerate(plan.placements):
        held = atlas[p.y : p.y + p.height, p.x : p.x + p.width]
        assert np.array_equal(held, transformed(views[p.example], p.transform))
        found, local = plan.locate(np.array([[p.y + 3, p.x + 5]]))
        assert found[0] == index and local[0].tolist() == [3, 5]
    assert plan.locate(np.array([[0, 0]]))[0][0] == -1  # a margin pixel: no placement
    assert SourceSet.from_json(json.loads(json.dumps(plan.to_json()))) == plan


# --- synthesis from several examples -------------------------------------------------------


def test_one_example_untransformed_is_todays_result() -> None:
    gravel = crop("gravel", 0, 0, 64, 64)
    today = quilting.synthesize(gravel, (80, 72), block=16, seed=3)
    for same in (
        quilting.synthesize([gravel], (80, 72), block=16, seed=3),
        quilting.synthesize(gravel, (80, 72), block=16, seed=3, transforms="none"),
        quilting.synthesize(gravel, (80, 72), block=16, seed=3, weights=[2.0]),
    ):
        assert same.image.tobytes() == today.image.tobytes()
        # (The meta records the options as given: weights=[2.0] there.)
        assert (
            json.loads(same.layout.to_json())["passes"]
            == json.loads(today.layout.to_json())["passes"]
        )
        assert same.layout.sources is None


@pytest.mark.parametrize("with_gl", [False, pytest.param(True, marks=pytest.mark.gl)])
@pytest.mark.parametrize("mode", ["cut", "overlap"])
def test_every_backend_gives_the_same_bytes_from_several_transformed_examples(
    request: pytest.FixtureRequest, with_gl: bool, mode: str
) -> None:
    results = {
        name: quilting.synthesize(
            examples(),
            (56, 60),
            block=BLOCK,
            seed=5,
            mode=mode,
            transforms="all",
            weights=[1, 2, 3],
            backend=b,
        )
        for name, b in backends(request, with_gl).items()
    }
    reference = results.pop("reference")
    assert reference.layout.sources is not None
    for name, result in results.items():
        assert result.image.tobytes() == reference.image.tobytes(), name
        ours, theirs = json.loads(result.layout.to_json()), json.loads(reference.layout.to_json())
        assert ours["passes"] == theirs["passes"] and ours["sources"] == theirs["sources"], name


@pytest.mark.parametrize("seed", range(4))
def test_the_rule_runs_over_every_example_at_once(seed: int) -> None:
    """With tolerance 0 the second block is the best match of its overlap across every
    transformed example: brute force over all of their blocks finds none better."""
    sources = [crop("gravel", 0, 0, 40, 40), crop("gravel", 60, 70, 36, 44)]
    result = quilting.synthesize(sources, (BLOCK, 3 * BLOCK), block=BLOCK, seed=seed,
                                 mode="overlap", tolerance=0.0, min_candidates=1,
                                 transforms="flips", blend="none")  # fmt: skip
    provenance = result.layout.provenance()
    grid = result.layout.passes[0].grid
    o, step = grid.overlap, grid.step

    def block(i: int, j: int) -> NDArray[np.float64]:
        turned = transformed(sources[provenance["example"][i, j]],
                             TRANSFORMS[provenance["transform"][i, j]])  # fmt: skip
        y, x = provenance["y"][i, j], provenance["x"][i, j]
        return turned[y : y + BLOCK, x : x + BLOCK].astype(np.float64)

    template = block(0, 0)[:, step : step + o]
    chosen = float(((block(0, 1)[:, :o] - template) ** 2).sum())
    best = np.inf
    for source in sources:
        for name in transform_names("flips"):
            turned = transformed(source, name).astype(np.float64)
            windows = np.lib.stride_tricks.sliding_window_view(turned, (BLOCK, o))
            costs = ((windows[: turned.shape[0] - BLOCK + 1, : turned.shape[1] - BLOCK + 1]
                      - template) ** 2).sum(axis=(-2, -1))  # fmt: skip
            best = min(best, float(costs.min()))
    assert chosen <= best * (1 + 1e-9) + 1e-9


def test_weights_steer_the_draws_between_examples() -> None:
    two = [crop("gravel", 0, 0, 40, 40), crop("gravel", 60, 60, 40, 40)]
    only_second = quilting.synthesize(two, (120, 120), block=BLOCK, seed=2, mode="random",
                                      weights=[1e-9, 1.0])  # fmt: skip
    assert (only_second.layout.provenance()["example"] == 1).all()
    shares = []
    for seed in range(3):
        result = quilting.synthesize(two, (160, 160), block=BLOCK, seed=seed, mode="random",
                                     weights=[3, 1])  # fmt: skip
        shares.append(float((result.layout.provenance()["example"] == 0).mean()))
    assert 0.65 < float(np.mean(shares)) < 0.85  # 0.75 expected
    even = quilting.synthesize(two, (160, 160), block=BLOCK, seed=0, mode="random")
    assert 0.35 < float((even.layout.provenance()["example"] == 0).mean()) < 0.65


def test_blocks_come_from_their_recorded_example_and_transform() -> None:
    """Away from its cuts every block shows its source: the example recorded in the layout,
    turned by the transform recorded, at the position recorded."""
    sources = examples()
    result = quilting.synthesize(sources, (64, 64), block=BLOCK, seed=4, transforms="all",
                                 blend="none")  # fmt: skip
    grid = result.layout.passes[0].grid
    provenance = result.layout.provenance()
    overlap = grid.overlap
    image = result.image
    for i in range(grid.rows):
        for j in range(grid.cols):
            y, x = i * grid.step, j * grid.step
            core = image[y + overlap : y + BLOCK - overlap, x + overlap : x + BLOCK - overlap]
            if core.shape[:2] != (BLOCK - 2 * overlap,) * 2:
                continue  # cropped at the output's edge
            turned = transformed(sources[provenance["example"][i, j]],
                                 TRANSFORMS[provenance["transform"][i, j]])  # fmt: skip
            sy, sx = provenance["y"][i, j], provenance["x"][i, j]
            expected = turned[
                sy + overlap : sy + BLOCK - overlap, sx + overlap : sx + BLOCK - overlap
            ]
            assert np.array_equal(core, expected), (i, j)
    transforms = np.unique(provenance["transform"])
    assert transforms.size > 2


@pytest.mark.parametrize("mode", ["cut", "walk", "random"])
def test_a_layout_of_several_examples_replays_and_round_trips(mode: str) -> None:
    sources = examples()
    result = quilting.synthesize(sources, (60, 52), block=BLOCK, seed=6, mode=mode,
                                 transforms="rotations")  # fmt: skip
    text = result.layout.to_json()
    loaded = quilting.Layout.from_json(text)
    assert json.loads(text)["version"] == 3 and loaded.sources == result.layout.sources
    assert np.array_equal(quilting.apply_layout(loaded, sources), result.image)
    with pytest.raises(LayoutError, match="one per example"):
        quilting.apply_layout(loaded, sources[:2])
    with pytest.raises(LayoutError, match="companion map 1"):
        quilting.apply_layout(loaded, [sources[0], sources[0], sources[2]])


def test_normal_map_companions_turn_with_their_blocks() -> None:
    """A normal map quilted with a layout of turned blocks shows, inside each block, the
    example's normals turned as the block was (vectors included)."""
    h = heights(40)
    normals = (normal_map(h, -1) * 255).round().astype(np.uint8)
    surface = (255 * (h - h.min()) / np.ptp(h)).astype(np.uint8)
    result = quilting.synthesize(surface, (60, 60), block=BLOCK, seed=2, transforms="all",
                                 blend="none")  # fmt: skip
    quilted = quilting.apply_layout(result.layout, normals, kind="normal")
    grid = result.layout.passes[0].grid
    provenance = result.layout.provenance()
    o = grid.overlap
    checked = 0
    for i in range(grid.rows - 1):
        for j in range(grid.cols - 1):
            name = TRANSFORMS[provenance["transform"][i, j]]
            sy, sx = provenance["y"][i, j], provenance["x"][i, j]
            y, x = i * grid.step, j * grid.step
            expected = turn_normals(normals, name)[sy + o : sy + BLOCK - o, sx + o : sx + BLOCK - o]
            core = quilted[y + o : y + BLOCK - o, x + o : x + BLOCK - o]
            # Renormalizing 8-bit vectors moves a component by at most one step.
            assert np.abs(core.astype(int) - expected.astype(int)).max() <= 1, (i, j, name)
            checked += name != "identity"
    assert checked > 0
    with pytest.raises(LayoutError):
        quilting.apply_layout(result.layout, surface, kind="normal")  # one channel


def test_alpha_mode_from_several_examples_keeps_every_backend_equal() -> None:
    cloud = texture("cloud_rgba")
    sources = [np.ascontiguousarray(cloud[:40, :40]), np.ascontiguousarray(cloud[40:84, 20:60])]
    fft = quilting.synthesize(sources, (48, 48), block=BLOCK, seed=1, backend=FFTBackend(),
                              transforms="flips")  # fmt: skip
    reference = quilting.synthesize(sources, (48, 48), block=BLOCK, seed=1,
                                    backend=ReferenceBackend(), transforms="flips")  # fmt: skip
    assert fft.image.tobytes() == reference.image.tobytes()
    assert fft.image.shape == (48, 48, 4)


@pytest.mark.parametrize(
    ("textures", "options", "error", "needle"),
    [
        ([], {}, InvalidImageError, "no texture"),
        (lambda e: [e[0], e[1][..., None].repeat(3, -1)], {}, InvalidImageError, "one kind"),
        (lambda e: [e[0], e[1].astype(np.uint16)], {}, InvalidImageError, "one kind"),
        (lambda e: [e[0], e[1][:10]], {}, InvalidParameterError, "texture 1"),
        (lambda e: e, {"weights": [1, 2]}, InvalidParameterError, "weights"),
        (lambda e: e, {"weights": [1, 0, 2]}, InvalidParameterError, "weights"),
        (lambda e: e, {"transforms": "spin"}, InvalidParameterError, "transforms"),
    ],
    ids=["empty", "channels", "dtype", "too small", "weights count", "zero weight", "transform"],
)
def test_bad_examples_are_refused_naming_the_problem(
    textures: Any, options: dict[str, Any], error: type[Exception], needle: str
) -> None:
    given = textures(examples()) if callable(textures) else textures
    with pytest.raises(error, match=needle):
        quilting.synthesize(given, (40, 40), block=BLOCK, **options)


def test_source_masks_go_one_per_example() -> None:
    sources = examples()
    masks: list[Any] = [None, np.zeros(sources[1].shape[:2], np.uint8), None]
    result = quilting.synthesize(sources, (60, 60), block=BLOCK, seed=3, source_mask=masks)
    assert 1 not in result.layout.provenance()["example"]
    with pytest.raises(InvalidImageError, match="list of 3 masks"):
        quilting.synthesize(sources, (60, 60), block=BLOCK, source_mask=masks[0:1])


def _continuing(result: quilting.Result) -> int:
    """How many blocks continue their left or top neighbour's source verbatim."""
    grid = result.layout.passes[0].grid
    positions = result.layout.passes[0].positions.astype(int)
    left = (positions[:, 1:] == positions[:, :-1] + np.array([0, grid.step])).all(axis=-1)
    top = (positions[1:] == positions[:-1] + np.array([grid.step, 0])).all(axis=-1)
    return int(left.sum() + top.sum())


@pytest.mark.parametrize("transforms", ["none", "all"])
def test_avoiding_continuations_breaks_verbatim_runs(transforms: str) -> None:
    """continuation='avoid' takes the neighbour's verbatim continuation out of the acceptable
    blocks: none is left where the default keeps many, and every backend agrees."""
    sample = crop("gravel", 0, 0, 64, 64)
    kwargs: dict[str, Any] = {"block": 16, "seed": 2, "transforms": transforms}
    allowed = quilting.synthesize(sample, (160, 160), continuation="allow", **kwargs)
    avoided = quilting.synthesize(sample, (160, 160), continuation="avoid", **kwargs)
    assert _continuing(allowed) > 5
    assert _continuing(avoided) == 0
    reference = quilting.synthesize(
        sample, (160, 160), continuation="avoid", backend=ReferenceBackend(), **kwargs
    )
    assert reference.image.tobytes() == avoided.image.tobytes()
    assert avoided.stats.largest_copy < allowed.stats.largest_copy


@pytest.mark.parametrize(
    ("texture", "transforms", "rule"),
    [("one", "none", "allow"), ("one", "rotations", "avoid"), ("three", "none", "avoid")],
)
def test_the_default_continuation_avoids_where_there_is_more_material(
    texture: str, transforms: str, rule: str
) -> None:
    """continuation='auto' is 'avoid' with transforms or several examples (the extra material
    leaves the copies as large otherwise), the paper's 'allow' for one example as it is; the
    layout records the rule that ran."""
    sources = examples() if texture == "three" else crop("gravel", 0, 0, 64, 64)
    kwargs: dict[str, Any] = {"block": BLOCK, "seed": 4, "transforms": transforms}
    default = quilting.synthesize(sources, (120, 120), **kwargs)
    explicit = quilting.synthesize(sources, (120, 120), continuation=rule, **kwargs)
    other = quilting.synthesize(
        sources, (120, 120), continuation="allow" if rule == "avoid" else "avoid", **kwargs
    )
    assert default.image.tobytes() == explicit.image.tobytes()
    assert default.image.tobytes() != other.image.tobytes()
    assert default.layout.meta["continuation"] == rule
