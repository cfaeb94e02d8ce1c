"""Companion kinds over HTTP: the ``companion_kinds`` field of /synthesize and /transfer, its
refusals, and the kinds carried with the job (the default server runs process workers)."""

from __future__ import annotations

import json
import pickle
from typing import Any

import httpx
import numpy as np
from service_helpers import assert_problem, job_id_of, synth_request, texture, wait_for

from quilting.io import encode_png, read_image
from quilting.service.jobs import JobInput


def _mask() -> bytes:
    """A 0/255 gray mask of the gravel texture's size (its brighter half)."""
    gravel = read_image(texture("gravel"))
    gray = gravel[..., :3].mean(axis=2) if gravel.ndim == 3 else gravel
    return encode_png(np.where(gray > np.median(gray), 255, 0).astype(np.uint8))


def _normals() -> bytes:
    """An RGB normal map ((n + 1) / 2 colours) of the gravel texture's size, bumpy."""
    gravel = read_image(texture("gravel")).astype(np.float64) / 255.0
    gray = gravel[..., :3].mean(axis=2) if gravel.ndim == 3 else gravel
    rng = np.random.default_rng(1)
    n = np.dstack([gray - 0.5, rng.uniform(-0.5, 0.5, gray.shape), np.ones(gray.shape)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    return encode_png(np.round((n + 1) / 2 * 255).astype(np.uint8))


def _post(
    client: httpx.Client,
    companions: dict[str, bytes],
    kinds: Any,
    options: dict[str, Any] | None = None,
) -> httpx.Response:
    request = synth_request(
        {"width": 160, "height": 120, "seed": 2, **(options or {})}, companions=companions
    )
    if kinds is not None:
        request["data"]["companion_kinds"] = kinds if isinstance(kinds, str) else json.dumps(kinds)
    return client.post("/synthesize", params={"wait": 0}, **request)


def _companion(client: httpx.Client, response: httpx.Response, name: str) -> np.ndarray:
    job_id = job_id_of(response)
    status = wait_for(client, job_id, timeout=120)
    assert status["status"] == "done", status
    return read_image(client.get(f"/jobs/{job_id}/result/{name}").content)


def test_a_hard_mask_keeps_its_values_and_a_blended_one_does_not(client: httpx.Client) -> None:
    mask = _mask()
    hard = _companion(client, _post(client, {"mask.png": mask}, {"mask": "hard"}), "mask")
    assert set(np.unique(hard).tolist()) <= {0, 255}
    # The default (seam blending) mixes the mask's values along the seams.
    blended = _companion(client, _post(client, {"mask.png": mask}, None), "mask")
    assert not set(np.unique(blended).tolist()) <= {0, 255}
    also = _companion(client, _post(client, {"mask.png": mask}, {"mask": "blend"}), "mask")
    np.testing.assert_array_equal(also, blended)


def test_a_normal_companion_comes_back_as_unit_vectors(client: httpx.Client) -> None:
    maps = {"n.png": _normals()}
    got = _companion(client, _post(client, maps, {"n": "normal"}), "n").astype(np.float64)
    lengths = np.linalg.norm(got[..., :3] / 255 * 2 - 1, axis=2)
    assert np.abs(lengths - 1).max() < 0.02
    blended = _companion(client, _post(client, maps, {}), "n").astype(np.float64)
    assert np.abs(np.linalg.norm(blended[..., :3] / 255 * 2 - 1, axis=2) - 1).max() > 0.02


def test_kinds_on_transfer(client: httpx.Client) -> None:
    from service_helpers import transfer_request

    request = transfer_request({"seed": 1, "block": 24}, companions={"mask.png": _mask()})
    request["data"]["companion_kinds"] = json.dumps({"mask": "hard"})
    response = client.post("/transfer", params={"wait": 0}, **request)
    assert set(np.unique(_companion(client, response, "mask")).tolist()) <= {0, 255}


def test_bad_companion_kinds_are_refused(client: httpx.Client) -> None:
    mask = {"mask.png": _mask()}
    cases: list[tuple[Any, str]] = [
        ({"other": "hard"}, "invalid_companion"),
        ({"mask": "soft"}, "invalid_parameter"),
        ({"mask": 3}, "invalid_parameter"),
        ("[1, 2]", "invalid_parameter"),
        ("{not json", "invalid_parameter"),
    ]
    for kinds, code in cases:
        assert_problem(_post(client, mask, kinds), 422, code, field="companion_kinds")
    # A gray mask is no normal map; a walk-mode layout has no unmixed rendering.
    assert_problem(
        _post(client, mask, {"mask": "normal"}), 422, "invalid_companion", field="companion_kinds"
    )
    assert_problem(
        _post(client, mask, {"mask": "hard"}, {"mode": "walk"}),
        422,
        "invalid_companion",
        field="companion_kinds",
    )
    # 'blend' with walk is fine.
    response = _post(client, mask, {"mask": "blend"}, {"mode": "walk"})
    assert response.status_code in (200, 202), response.text


def test_the_schema_documents_the_field(client: httpx.Client) -> None:
    schema = client.get("/openapi.json").json()
    for path in ("/synthesize", "/transfer"):
        body = schema["paths"][path]["post"]["requestBody"]["content"]["multipart/form-data"]
        ref = body["schema"]["$ref"].rsplit("/", 1)[-1]
        props = schema["components"]["schemas"][ref]["properties"]
        assert "companion_kinds" in props
        assert "'hard'" in props["companion_kinds"]["description"]


def test_job_input_carries_kinds_and_old_inputs_load() -> None:
    spec = JobInput(b"t", {"m": b"x"}, {}, 4, 4, companion_kinds={"m": "hard"})
    assert JobInput.from_bytes(spec.to_bytes()).kind_of("m") == "hard"
    assert pickle.loads(pickle.dumps(spec)).kind_of("m") == "hard"
    old = JobInput(b"t", {"m": b"x"}, {}, 4, 4)
    # An input written before kinds existed: the header has no companion_kinds.
    data = old.to_bytes()
    magic = data.index(b"\n") + 1
    size = int.from_bytes(data[magic : magic + 4], "big")
    header = json.loads(data[magic + 4 : magic + 4 + size])
    del header["companion_kinds"]
    text = json.dumps(header).encode()
    data = data[:magic] + len(text).to_bytes(4, "big") + text + data[magic + 4 + size :]
    assert JobInput.from_bytes(data).kind_of("m") == "blend"
    state = dict(old.__dict__)
    del state["companion_kinds"]
    revived = JobInput.__new__(JobInput)
    revived.__setstate__(state)
    assert revived.kind_of("m") == "blend"


def test_a_deeply_nested_companion_kinds_is_refused_not_a_crash(client: httpx.Client) -> None:
    """The field is depth-checked before it is parsed, as options are: a nesting deep enough
    to exhaust the JSON parser's recursion gets a 422, not a 500."""
    deep = "[" * 5000 + "]" * 5000
    response = _post(client, {"mask.png": _mask()}, deep)
    assert_problem(response, 422, "invalid_parameter")
    assert "levels deep" in response.json()["detail"]
