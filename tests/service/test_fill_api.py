"""Filling and extending over ``POST /fill`` and ``POST /extend``: the pixels outside the mask
(the image placed in an extension) come back byte for byte, the result is the Python API's,
companions are filled along, the job contract holds (wait, events, cancel, idempotency), and
every bad input is answered with its 4xx problem before anything is queued."""

from __future__ import annotations

import asyncio
import io
import json
import pickle
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from cluster import RedisServer, WorkerProcess, need_redis
from PIL import Image
from service_helpers import (
    FINAL,
    Server,
    assert_png,
    assert_problem,
    job_id_of,
    parse_sse,
    png_image,
    texture,
    tile,
    wait_for,
)

import quilting
from quilting.io import encode_png
from quilting.service.jobs import JobInput
from quilting_client import AsyncClient, Client, ValidationError

SIZE = 96
#: A colour image of SIZE x SIZE and a rectangle to fill in it.
IMAGE = quilting.read_image(texture("hubble"))[:SIZE, :SIZE]
HOLE = np.s_[30:62, 40:70]
OPTIONS = {"block": 16, "seed": 5, "backend": "fft"}


def _mask(size: tuple[int, int] = (SIZE, SIZE), hole: Any = HOLE) -> np.ndarray:
    """A gray mask of ``size`` (height, width): white over ``hole``, black elsewhere."""
    mask = np.zeros(size, dtype=np.uint8)
    mask[hole] = 255
    return mask


def _png(image: np.ndarray) -> bytes:
    return encode_png(image)


def _decoded(data: bytes) -> np.ndarray:
    return quilting.read_image(data)


def _files(
    image: bytes | None = None,
    mask: bytes | None = None,
    texture_part: bytes | None = None,
    companions: dict[str, bytes] | None = None,
) -> list[tuple[str, tuple[str, bytes, str]]]:
    files = [("image", ("photo.png", image or _png(IMAGE), "image/png"))]
    if mask is not None:
        files.append(("mask", ("mask.png", mask, "image/png")))
    if texture_part is not None:
        files.append(("texture", ("texture.png", texture_part, "image/png")))
    for name, data in (companions or {}).items():
        files.append(("companion", (f"{name}.png", data, "image/png")))
    return files


def _fill(
    client: httpx.Client,
    options: dict[str, Any] | str | None = None,
    *,
    wait: float = 60,
    mask: bytes | None = None,
    with_mask: bool = True,
    headers: dict[str, str] | None = None,
    **files: Any,
) -> httpx.Response:
    data = {}
    if options is not None:
        data["options"] = options if isinstance(options, str) else json.dumps(options)
    if with_mask and mask is None:
        mask = _png(_mask())
    return client.post(
        "/fill",
        params={"wait": wait},
        files=_files(mask=mask, **files),
        data=data,
        headers=headers,
    )


def _extend(
    client: httpx.Client,
    options: dict[str, Any] | str | None = None,
    *,
    wait: float = 60,
    image: bytes | None = None,
    companions: dict[str, bytes] | None = None,
) -> httpx.Response:
    data = {}
    if options is not None:
        data["options"] = options if isinstance(options, str) else json.dumps(options)
    files = _files(image=image, companions=companions)
    return client.post("/extend", params={"wait": wait}, files=files, data=data)


def _status(client: httpx.Client, response: httpx.Response) -> dict[str, Any]:
    status = wait_for(client, job_id_of(response), FINAL)
    assert status["status"] == "done", status
    return status


# --- fill ------------------------------------------------------------------------------------


def test_fill_keeps_every_pixel_outside_the_mask_and_is_the_python_result(
    client: httpx.Client,
) -> None:
    mask = _mask()
    response = _fill(client, OPTIONS)
    out = np.asarray(assert_png(response, SIZE, SIZE))
    assert out.dtype == IMAGE.dtype and out.shape == IMAGE.shape
    kept = mask == 0
    assert np.array_equal(out[kept], IMAGE[kept])
    assert not np.array_equal(out[~kept], IMAGE[~kept])  # the hole was synthesized again
    assert np.array_equal(out, quilting.fill(IMAGE, mask, **OPTIONS).image)
    disposition = response.headers["Content-Disposition"]
    assert 'filename="photo-fill-96x96-seed5.png"' in disposition
    status = _status(client, response)
    assert status["operation"] == "fill"
    assert (status["width"], status["height"]) == (SIZE, SIZE)
    assert status["layout"] == f"/jobs/{status['id']}/layout" and status["companions"] == []
    assert status["backend"] == "fft"
    assert status["stats"]["filled_pixels"] == int(mask.astype(bool).sum())
    assert status["stats"]["blocks"] > 0 and status["stats"]["seam_error_mean"] >= 0
    # The layout replays the fill: a companion (here the image itself, unblended) filled by
    # it is what the service would have filled; the seams lie around the hole.
    layout = client.get(f"/jobs/{status['id']}/layout")
    assert layout.status_code == 200, layout.text
    saved = quilting.FillLayout.from_json(layout.content)
    python = quilting.fill(IMAGE, mask, **OPTIONS)
    assert np.array_equal(saved.provenance()[0], python.source_rows)
    assert np.array_equal(saved.apply(IMAGE), python.apply(IMAGE))
    seams = client.get(f"/jobs/{status['id']}/seams")
    assert seams.status_code == 200, seams.text
    drawn = np.asarray(png_image(seams.content))[..., 3] > 0
    assert np.array_equal(drawn, saved.seam_mask()) and drawn.any()
    meta = json.loads(png_image(response.content).info["quilting"])
    assert meta["operation"] == "fill" and meta["block"] == 16 and meta["seed"] == 5


def test_the_same_seed_gives_the_same_bytes_another_seed_other_bytes(
    client: httpx.Client,
) -> None:
    first = _fill(client, OPTIONS)
    second = _fill(client, OPTIONS)
    assert job_id_of(first) != job_id_of(second)
    assert first.content == second.content
    other = _fill(client, {**OPTIONS, "seed": 6})
    assert np.array_equal(np.asarray(png_image(other.content))[_mask() == 0], IMAGE[_mask() == 0])
    assert other.content != first.content


def test_a_mask_with_alpha_keeps_its_transparent_pixels(client: httpx.Client) -> None:
    """RGBA mask: white where alpha is 255 fills; white where alpha is 0 is kept."""
    rgba = np.zeros((SIZE, SIZE, 4), dtype=np.uint8)
    rgba[..., :3] = 255  # white everywhere...
    rgba[(*HOLE, 3)] = 255  # ...but opaque only over the hole
    response = _fill(client, OPTIONS, mask=_png(rgba))
    out = np.asarray(assert_png(response, SIZE, SIZE))
    assert np.array_equal(out, quilting.fill(IMAGE, _mask(), **OPTIONS).image)


def test_sixteen_bit_images_keep_their_depth_and_their_pixels(client: httpx.Client) -> None:
    deep = (
        IMAGE.astype(np.uint16) * 257 + np.arange(SIZE, dtype=np.uint16)[:, None, None]
    ) & 0xFFFF
    response = _fill(client, OPTIONS, image=_png(deep))
    assert response.status_code == 200, response.text
    out = _decoded(response.content)
    assert out.dtype == np.uint16
    kept = _mask() == 0
    assert np.array_equal(out[kept], deep[kept])


def test_an_empty_mask_returns_the_image_as_it_is(client: httpx.Client) -> None:
    response = _fill(client, {"block": 500}, mask=_png(_mask(hole=np.s_[0:0, 0:0])))
    assert np.array_equal(np.asarray(assert_png(response, SIZE, SIZE)), IMAGE)


def test_a_texture_gives_the_blocks_and_fills_a_whole_image(client: httpx.Client) -> None:
    source = quilting.read_image(texture("hubble"))[100:228, 100:228]
    everything = _png(np.full((SIZE, SIZE), 255, dtype=np.uint8))
    response = _fill(client, OPTIONS, mask=everything, texture_part=_png(source))
    out = np.asarray(assert_png(response, SIZE, SIZE))
    expected = quilting.fill(IMAGE, np.ones((SIZE, SIZE), bool), texture=source, **OPTIONS)
    assert np.array_equal(out, expected.image)


def test_companions_are_filled_the_same_way(client: httpx.Client) -> None:
    normal = quilting.read_image(texture("gravel"))[:SIZE, :SIZE]
    response = _fill(client, OPTIONS, companions={"height": _png(normal)})
    assert response.status_code == 200, response.text
    status = _status(client, response)
    assert status["companions"] == ["height"]
    filled = client.get(f"/jobs/{status['id']}/result/height")
    out = np.asarray(assert_png(filled, SIZE, SIZE))
    kept = _mask() == 0
    assert np.array_equal(out[kept], normal[kept])
    assert np.array_equal(out, quilting.fill(IMAGE, _mask(), **OPTIONS).apply(normal))
    assert 'filename="photo-fill-96x96-seed5-height.png"' in filled.headers["Content-Disposition"]


def test_fill_follows_the_job_contract(client: httpx.Client) -> None:
    """wait=0: 202 and a Location; progress events end with done; the result is served; a
    finished job cannot be cancelled."""
    response = _fill(client, OPTIONS, wait=0)
    assert response.status_code in (200, 202), response.text
    job_id = job_id_of(response)
    status = wait_for(client, job_id)
    assert status["status"] == "done" and status["progress"] == 1.0
    assert status["result"] == f"/jobs/{job_id}/result"
    assert_png(client.get(f"/jobs/{job_id}/result"), SIZE, SIZE)
    with client.stream("GET", f"/jobs/{job_id}/events") as events:
        assert events.status_code == 200
        received = parse_sse(list(events.iter_lines()))
    assert received[-1][0] == "done"
    assert json.loads(received[-1][1])["operation"] == "fill"
    assert_problem(client.delete(f"/jobs/{job_id}"), 409, "job_finished")


def test_a_running_fill_can_be_cancelled(client: httpx.Client) -> None:
    image = quilting.read_image(texture("gravel"))
    big = _png(_mask((256, 256), np.s_[20:236, 20:236]))
    response = _fill(client, {"block": 8, "seed": 1}, wait=0, image=_png(image), mask=big)
    job_id = job_id_of(response)
    cancelled = client.delete(f"/jobs/{job_id}")
    if cancelled.status_code == 409:  # it was quicker than the request
        assert_problem(cancelled, 409, "job_finished")
        return
    assert cancelled.status_code == 202, cancelled.text
    assert wait_for(client, job_id)["status"] == "cancelled"


def test_an_idempotency_key_gives_the_same_job_once(client: httpx.Client) -> None:
    key = {"Idempotency-Key": "fill-once-7f1c"}
    first = _fill(client, OPTIONS, headers=key)
    again = _fill(client, OPTIONS, headers=key)
    assert job_id_of(first) == job_id_of(again)
    other_mask = _png(_mask(hole=np.s_[10:30, 10:30]))
    assert_problem(
        _fill(client, OPTIONS, mask=other_mask, headers=key), 409, "idempotency_conflict"
    )


# --- fill's refusals -------------------------------------------------------------------------


def test_a_mask_of_another_size_is_refused_naming_both_sizes(client: httpx.Client) -> None:
    response = _fill(client, OPTIONS, mask=_png(_mask((SIZE, SIZE - 1))))
    body = assert_problem(response, 422, "invalid_image", field="mask")
    assert "95x96" in body["detail"] and "96x96" in body["detail"], body["detail"]


def test_a_mask_covering_everything_needs_a_texture(client: httpx.Client) -> None:
    everything = _png(np.full((SIZE, SIZE), 255, dtype=np.uint8))
    body = assert_problem(_fill(client, OPTIONS, mask=everything), 422, "invalid_image", "mask")
    assert "texture" in body["detail"]


def test_a_block_that_fits_nowhere_names_the_largest_that_does(client: httpx.Client) -> None:
    wide = _png(_mask(hole=np.s_[20:76, :]))  # a band across: 20 rows above, 20 below
    body = assert_problem(_fill(client, {"block": 40}, mask=wide), 422, "invalid_parameter")
    assert body["field"] == "block"
    assert "block=20" in body["detail"], body["detail"]
    larger = assert_problem(_fill(client, {"block": 200}), 422, "invalid_parameter", "block")
    assert "96" in larger["detail"]


@pytest.mark.parametrize(
    ("options", "code", "field"),
    [
        ({"block": 2}, "invalid_parameter", "block"),
        ({"block": "16"}, "invalid_parameter", "block"),
        ({"blend": "feather"}, "invalid_parameter", "blend"),
        ({"tolerance": -1}, "invalid_parameter", "tolerance"),
        ({"block": 16, "overlap": 8}, "invalid_parameter", "overlap"),
        ({"backend": "cuda"}, "invalid_parameter", "backend"),
        ({"width": 64}, "invalid_options", "width"),
        ({"top": 8}, "invalid_options", "top"),
        ("[1, 2]", "invalid_options", "options"),
        ("{not json", "invalid_options", "options"),
    ],
)
def test_bad_option_values_are_refused(
    client: httpx.Client, options: dict[str, Any] | str, code: str, field: str
) -> None:
    assert_problem(_fill(client, options), 422, code, field)


def test_bad_parts_are_refused(client: httpx.Client) -> None:
    assert_problem(_fill(client, OPTIONS, with_mask=False), 422, "missing_field", "mask")
    not_an_image = _fill(client, OPTIONS, mask=b"GIF89a not an image")
    assert_problem(not_an_image, 415, "unsupported_media_type", "mask")
    gray_texture = _png(quilting.read_image(texture("gravel"))[:64, :64])
    body = assert_problem(
        _fill(client, OPTIONS, texture_part=gray_texture), 422, "invalid_image", "texture"
    )
    assert "channels" in body["detail"]
    small = _png(quilting.read_image(texture("gravel"))[:64, :64])
    assert_problem(
        _fill(client, OPTIONS, companions={"height": small}), 422, "invalid_companion", "companion"
    )
    same = _png(IMAGE)
    assert_problem(
        _fill(client, OPTIONS, texture_part=same, companions={"height": same}),
        422,
        "invalid_companion",
        "companion",
    )
    twice = [*_files(mask=_png(_mask())), ("mask", ("m.png", _png(_mask()), "image/png"))]
    assert_problem(client.post("/fill", files=twice), 422, "duplicate_part", "mask")


def test_a_fill_over_the_budget_is_refused_before_it_is_queued(client: httpx.Client) -> None:
    """A large flat image (a few kB of PNG) with a large hole: predicted over the memory and
    time budgets once the mask is read, refused with job_too_large; never queued."""
    buffer = io.BytesIO()
    Image.new("RGB", (4000, 4000), 90).save(buffer, format="PNG")
    mask = io.BytesIO()
    hole = Image.new("L", (4000, 4000), 0)
    hole.paste(255, (100, 100, 3900, 3900))
    hole.save(mask, format="PNG")
    response = _fill(client, {}, image=buffer.getvalue(), mask=mask.getvalue())
    body = assert_problem(response, 422, "job_too_large")
    assert "job_memory_bytes" in body["detail"] and body["budget_bytes"] > 0
    assert "fill a smaller hole" in body["detail"]
    assert "X-Job-Id" not in response.headers
    assert client.get("/healthz").status_code == 200


# --- extend ----------------------------------------------------------------------------------


def test_extend_places_the_image_unchanged_on_a_larger_canvas(client: httpx.Client) -> None:
    image = IMAGE[:64, :80]
    margins = {"top": 12, "bottom": 0, "left": 20, "right": 7}
    options = {**OPTIONS, **margins}
    normal = quilting.read_image(texture("gravel"))[:64, :80]
    response = _extend(client, options, image=_png(image), companions={"normal": _png(normal)})
    width, height = 80 + 20 + 7, 64 + 12
    out = np.asarray(assert_png(response, width, height))
    assert np.array_equal(out[12 : 12 + 64, 20 : 20 + 80], image)
    expected = quilting.extend(image, **options)
    assert np.array_equal(out, expected.image)
    assert 'filename="photo-extend-107x76-seed5.png"' in response.headers["Content-Disposition"]
    status = _status(client, response)
    assert status["operation"] == "extend" and (status["width"], status["height"]) == (
        width,
        height,
    )
    assert status["stats"]["filled_pixels"] == width * height - 64 * 80
    extended = client.get(f"/jobs/{status['id']}/result/normal")
    companion = np.asarray(assert_png(extended, width, height))
    assert np.array_equal(companion[12 : 12 + 64, 20 : 20 + 80], normal)
    assert np.array_equal(companion, expected.apply(normal))


def test_extend_without_margins_is_the_image(client: httpx.Client) -> None:
    response = _extend(client, OPTIONS)
    assert np.array_equal(np.asarray(assert_png(response, SIZE, SIZE)), IMAGE)


@pytest.mark.parametrize(
    ("options", "code", "field"),
    [
        ({"top": -1}, "invalid_parameter", "top"),
        ({"left": 1.5}, "invalid_parameter", "left"),
        ({"right": 20000}, "invalid_parameter", "right"),
        ({"bottom": 16300}, "invalid_parameter", "bottom"),
        ({"top": 8, "block": 200}, "invalid_parameter", "block"),
        ({"top": 8, "margin": 3}, "invalid_options", "margin"),
        ({"top": 8, "width": 300}, "invalid_options", "width"),
    ],
)
def test_bad_extensions_are_refused(
    client: httpx.Client, options: dict[str, Any], code: str, field: str
) -> None:
    body = assert_problem(_extend(client, options), 422, code, field)
    if field == "bottom":
        assert "96x16396" in body["detail"] and "max_side" in body["detail"]


def test_an_extension_over_the_budget_is_refused_at_once(client: httpx.Client) -> None:
    buffer = io.BytesIO()
    Image.new("RGB", (2000, 2000), 90).save(buffer, format="PNG")
    options = {"top": 3000, "bottom": 3000, "left": 3000, "right": 3000}
    response = _extend(client, options, image=buffer.getvalue())
    body = assert_problem(response, 422, "job_too_large")
    assert "job_memory_bytes" in body["detail"]


# --- tile by filling -------------------------------------------------------------------------


def test_tile_by_filling_is_the_python_result(client: httpx.Client) -> None:
    image = quilting.read_image(texture("brick"))[:128, :128]
    response = tile(client, _png(image), {"method": "fill", "seed": 3, "blend": "none"})
    out = np.asarray(assert_png(response, 128, 128))
    expected = quilting.make_tileable(image, method="fill", seed=3, blend="none").image
    assert np.array_equal(out, expected)
    cut = tile(client, _png(image), {"method": "cut", "blend": "none"})
    assert cut.status_code == 200 and cut.content != response.content
    assert_problem(
        tile(client, _png(image), {"method": "paint"}), 422, "invalid_parameter", "method"
    )


def test_tile_by_filling_is_costed_as_a_fill(client: httpx.Client) -> None:
    """A flat image the cut method tiles within the sandbox's budget is refused by the fill
    method's cost (a fill of the whole image) before the sandbox sees it, naming the largest
    image that fits (the caller gave no hole to make smaller)."""
    buffer = io.BytesIO()
    Image.new("RGB", (4000, 4000), 90).save(buffer, format="PNG")
    body = assert_problem(tile(client, buffer.getvalue(), {"method": "fill"}), 422, "job_too_large")
    assert "use an image of at most" in body["detail"] and "hole" not in body["detail"]


# --- the Python client, live --------------------------------------------------------------------


def test_the_client_fills_as_the_python_api(server: Server) -> None:
    normal = quilting.read_image(texture("gravel"))[:SIZE, :SIZE]
    with Client(server.url) as client:
        result = client.fill(
            _png(IMAGE), _png(_mask()), companions={"normal": _png(normal)}, **OPTIONS
        )
        expected = quilting.fill(IMAGE, _mask(), **OPTIONS)
        assert np.array_equal(_decoded(result), expected.image)
        assert np.array_equal(_decoded(result.companions["normal"]), expected.apply(normal))
        status = client.status(result.job_id or "")
        assert status.operation == "fill" and status.layout is not None
        with pytest.raises(ValidationError) as caught:
            client.fill(_png(IMAGE), _png(_mask((SIZE, SIZE - 1))))
        assert caught.value.code == "invalid_image" and caught.value.field == "mask"


def test_the_async_client_extends_as_the_python_api(server: Server) -> None:
    image = IMAGE[:64, :64]

    async def run() -> tuple[bytes, str]:
        async with AsyncClient(server.url) as client:
            job = await client.submit_extend(_png(image), top=16, left=8, **OPTIONS)
            done = await client.wait(job.id, timeout=60)
            return await client.result(done.id), done.operation

    png, operation = asyncio.run(run())
    assert operation == "extend"
    expected = quilting.extend(image, top=16, left=8, **OPTIONS).image
    assert np.array_equal(_decoded(png), expected)


# --- the distributed queue --------------------------------------------------------------------


def test_fill_and_extend_through_redis_and_a_worker(tmp_path: Path, log_dir: Path) -> None:
    """A replica on Redis and a ``quilting worker``: the job's input (image, mask, texture,
    companions) crosses as bytes; the results are the Python API's."""
    need_redis()
    redis = RedisServer(tmp_path).start()
    env = {
        "QUILTING_QUEUE": redis.url,
        "QUILTING_HEARTBEAT_TIMEOUT_S": "30",
        "QUILTING_DRAIN_GRACE_S": "5",
    }
    api, worker = Server("fill-redis", env, log_dir), WorkerProcess("fill-w0", env, log_dir)
    try:
        api.start()
        worker.start()
        normal = quilting.read_image(texture("gravel"))[:SIZE, :SIZE]
        with api.client() as client:
            response = _fill(client, OPTIONS, companions={"normal": _png(normal)})
            expected = quilting.fill(IMAGE, _mask(), **OPTIONS)
            assert np.array_equal(np.asarray(assert_png(response, SIZE, SIZE)), expected.image)
            status = _status(client, response)
            companion = client.get(f"/jobs/{status['id']}/result/normal")
            assert np.array_equal(
                np.asarray(assert_png(companion, SIZE, SIZE)), expected.apply(normal)
            )
            source = quilting.read_image(texture("hubble"))[100:228, 100:228]
            everything = _png(np.full((SIZE, SIZE), 255, dtype=np.uint8))
            with_texture = _fill(client, OPTIONS, mask=everything, texture_part=_png(source))
            whole = quilting.fill(IMAGE, np.ones((SIZE, SIZE), bool), texture=source, **OPTIONS)
            assert np.array_equal(np.asarray(assert_png(with_texture, SIZE, SIZE)), whole.image)
            extended = _extend(client, {**OPTIONS, "bottom": 20})
            grown = quilting.extend(IMAGE, bottom=20, **OPTIONS).image
            assert np.array_equal(np.asarray(assert_png(extended, SIZE, SIZE + 20)), grown)
            assert _status(client, extended)["operation"] == "extend"
    finally:
        worker.stop()
        api.stop()
        redis.stop()


# --- the job's input -------------------------------------------------------------------------


def test_a_fill_s_input_travels_whole() -> None:
    """The mask and the texture go through the distributed queue's bytes and a pickle; an input
    written before fills loads without them."""
    spec = JobInput(
        b"image", {"n": b"normal"}, {"block": 8}, 4, 4, operation="fill", mask=b"m", source=b"t"
    )
    again = JobInput.from_bytes(spec.to_bytes())
    assert (again.mask, again.source, again.operation) == (b"m", b"t", "fill")
    assert again.companions == {"n": b"normal"} and again.texture == b"image"
    assert pickle.loads(pickle.dumps(spec)).mask == b"m"
    old = JobInput(b"t", {}, {}, 4, 4)
    state = dict(old.__dict__)
    del state["mask"], state["source"]
    revived = JobInput.__new__(JobInput)
    revived.__setstate__(state)
    assert revived.mask is None and revived.source is None


def test_the_schemas_are_published(server: Server) -> None:
    schema = httpx.get(server.url + "/openapi.json", timeout=30).json()
    schemas = schema["components"]["schemas"]
    fill_props = schemas["FillOptions"]["properties"]
    assert fill_props["blend"]["enum"] == ["none", "poisson"]
    assert {"top", "bottom", "left", "right"}.isdisjoint(fill_props)
    extend_props = schemas["ExtendOptions"]["properties"]
    assert set(fill_props) < set(extend_props)
    assert extend_props["top"]["minimum"] == 0
    assert schemas["TileOptions"]["properties"]["method"]["enum"] == ["cut", "fill"]
    for path in ("/fill", "/extend"):
        post = schema["paths"][path]["post"]
        assert {"200", "202", "422"} <= set(post["responses"])
    body = schema["paths"]["/fill"]["post"]["requestBody"]["content"]["multipart/form-data"]
    ref = body["schema"]["$ref"].rsplit("/", 1)[-1]
    assert set(schemas[ref]["required"]) == {"image", "mask"}
