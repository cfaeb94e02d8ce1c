"""Property-based tests from the live server's OpenAPI document (schemathesis + hypothesis).

For every operation, generated requests never get a 5xx, every error is a problem document, and
responses the schema declares conform to it. Job paths are sometimes pointed at a real, finished
job so that the success responses are exercised too. A second property sends real textures with
generated options: the service answers 200/202/422, and accepted jobs end done or failed with an
engine error, never an internal error.
"""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from typing import Any

import httpx
import numpy as np
import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
)
from service_helpers import (
    FINAL,
    Server,
    assert_problem,
    job_id_of,
    png_image,
    synth,
    synth_request,
    texture,
    transfer_request,
    wait_for,
)

OPERATIONS = [
    "synthesize",
    "transfer",
    "fill",
    "extend",
    "wang_tiles",
    "tile",
    "get_job",
    "get_result",
    "get_companion",
    "get_layout",
    "get_manifest",
    "job_events",
    "cancel_job",
    "healthz",
    "readyz",
    "metrics",
]
PROPERTY_SETTINGS = settings(
    max_examples=25,
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
    derandomize=True,
)
#: The real textures the generated-options properties send.
TEXTURE_NAMES = ["gravel", "brick", "hubble", "wood"]


def check_generated_answer(
    client: httpx.Client,
    response: httpx.Response,
    seen: list[int],
    codes: tuple[str, ...],
    operation: str | None = None,
) -> httpx.Response | None:
    """What every request with generated options must get: 200/202, or a 422 problem (one of
    ``codes``) naming its field; an accepted job ends done, its result served, or failed with
    an engine error, never ``internal_error``. The status goes to ``seen``.

    Returns
    -------
    httpx.Response | None
        The result of a done job (for the caller's own checks), None otherwise.
    """
    assert response.status_code in (200, 202, 422), response.text
    seen.append(response.status_code)
    if response.status_code == 422:
        body = assert_problem(response, 422, codes)
        assert body.get("field"), body
        return None
    status = wait_for(client, job_id_of(response), FINAL, timeout=30)
    assert status["status"] in ("done", "failed"), status
    if operation is not None:
        assert status["operation"] == operation
    if status["status"] == "failed":
        assert status["error"]["code"] != "internal_error", status
        return None
    result = client.get(f"/jobs/{status['id']}/result")
    assert result.status_code == 200
    return result


def assert_not_vacuous(seen: list[int]) -> None:
    """Both accepted jobs and refused options were exercised."""
    assert sum(code != 422 for code in seen) >= 10, seen
    assert seen.count(422) >= 3, seen


@pytest.fixture(scope="module")
def api_schema(server: Server) -> Any:
    return schemathesis.openapi.from_url(server.url + "/openapi.json")


@pytest.fixture(scope="module")
def real_job(server: Server) -> str:
    """A finished job with a companion named ``normal``."""
    with server.client() as client:
        response = synth(
            client, {"width": 80, "height": 80}, companions={"normal.png": texture("gravel")}
        )
        return job_id_of(response)


def _operation(api_schema: Any, operation_id: str) -> Any:
    for result in api_schema.get_all_operations():
        operation = result.ok()
        if operation.definition.raw.get("operationId") == operation_id:
            return operation
    raise AssertionError(f"no operation {operation_id}")


def test_schema_has_the_contract_operations(api_schema: Any) -> None:
    found = {
        result.ok().definition.raw.get("operationId") for result in api_schema.get_all_operations()
    }
    assert set(OPERATIONS) <= found, found
    schemas = api_schema.raw_schema["components"]["schemas"]
    assert {
        "SynthesizeOptions",
        "TransferOptions",
        "TileOptions",
        "FillOptions",
        "ExtendOptions",
        "WangOptions",
    } <= set(schemas)


def _draw_case(data: st.DataObject, operation: Any, real_job: str) -> Any:
    case = data.draw(operation.as_strategy())
    if case.path_parameters and "job_id" in case.path_parameters and data.draw(st.booleans()):
        case.path_parameters["job_id"] = real_job
        if "name" in case.path_parameters and data.draw(st.booleans()):
            case.path_parameters["name"] = "normal"
    return case


def _check_error_is_problem(response: Any) -> None:
    status = response.status_code
    assert status < 500, f"{status}: {response.content[:500]!r}"
    if status >= 400:
        content_type = response.headers.get("content-type", [""])[0]
        assert content_type.split(";")[0] == "application/problem+json", (status, content_type)
        body = json.loads(response.content)
        assert body["status"] == status and isinstance(body["code"], str), body


def _each_answer(
    api_schema: Any,
    real_job: str,
    server: Server,
    operation_id: str,
    check: Callable[[Any, Any], None],
) -> None:
    """Generated requests of the operation (:data:`PROPERTY_SETTINGS`) sent to the server;
    ``check(case, response)`` for each."""
    operation = _operation(api_schema, operation_id)

    @PROPERTY_SETTINGS
    @given(data=st.data())
    def run(data: st.DataObject) -> None:
        case = _draw_case(data, operation, real_job)
        check(case, case.call(base_url=server.url, timeout=30))

    run()


@pytest.mark.parametrize("operation_id", OPERATIONS)
def test_no_server_errors(
    api_schema: Any, real_job: str, server: Server, operation_id: str
) -> None:
    def check(case: Any, response: Any) -> None:
        _check_error_is_problem(response)
        case.validate_response(response, checks=[not_a_server_error])

    _each_answer(api_schema, real_job, server, operation_id, check)


@pytest.mark.parametrize("operation_id", OPERATIONS)
def test_responses_conform_to_schema(
    api_schema: Any, real_job: str, server: Server, operation_id: str
) -> None:
    """Responses whose status the schema declares have its media type and body schema."""

    def check(case: Any, response: Any) -> None:
        checks = [response_schema_conformance, content_type_conformance]
        case.validate_response(response, checks=checks)

    _each_answer(api_schema, real_job, server, operation_id, check)


# --- real textures, generated options --------------------------------------------------------


@st.composite
def options_strategy(draw: st.DrawFn) -> dict[str, Any]:
    """Options that are mostly valid (so that jobs run), with a sprinkle of invalid values."""

    def pick(valid: st.SearchStrategy[Any], invalid: st.SearchStrategy[Any]) -> Any:
        # 7, not 0: hypothesis favours the ends of a range.
        return draw(invalid) if draw(st.integers(0, 9)) == 7 else draw(valid)

    options = {
        "width": pick(st.integers(1, 96), st.integers(-3, 0)),
        "height": pick(st.integers(1, 96), st.integers(-3, 0)),
    }
    optional = {
        # Blocks of 16+ keep the jobs short (the fft backend searches the whole texture).
        "block": (st.integers(16, 64), st.integers(-2, 2) | st.integers(257, 400)),
        "overlap": (st.none() | st.integers(1, 12), st.integers(-1, 0) | st.integers(40, 99)),
        "tolerance": (
            st.floats(0, 10),
            st.floats(-1, -0.001) | st.floats(10.001, 20) | st.just(float("nan")),
        ),
        "mode": (st.sampled_from(["cut", "overlap", "random"]), st.sampled_from(["CUT", ""])),
        "seed": (st.integers(0, 2**64 - 1), st.just(-1) | st.just(2**64)),
        "backend": (st.sampled_from(["auto", "fft"]), st.sampled_from(["gpu", ""])),
        "min_candidates": (st.integers(1, 20), st.integers(-1, 0)),
    }
    for key, (valid, invalid) in optional.items():
        if draw(st.booleans()):
            options[key] = pick(valid, invalid)
    if draw(st.integers(0, 19)) == 7:
        options["extra"] = 1
    return options


def test_generated_options_on_real_textures(server: Server) -> None:
    seen: list[int] = []
    with server.client() as client:

        @settings(PROPERTY_SETTINGS, max_examples=40)
        @given(options=options_strategy(), name=st.sampled_from(TEXTURE_NAMES))
        def run(options: dict[str, Any], name: str) -> None:
            response = client.post(
                "/synthesize", params={"wait": 0}, **synth_request(options, tex=name)
            )
            codes = ("invalid_parameter", "invalid_options", "missing_field")
            check_generated_answer(client, response, seen, codes)

        run()
    assert_not_vacuous(seen)


@st.composite
def transfer_options_strategy(draw: st.DrawFn) -> dict[str, Any]:
    """Transfer options, mostly valid, with a sprinkle of invalid values (see above)."""

    def pick(valid: st.SearchStrategy[Any], invalid: st.SearchStrategy[Any]) -> Any:
        return draw(invalid) if draw(st.integers(0, 9)) == 7 else draw(valid)

    optional = {
        # The targets are at most 64x64: blocks of 8+ and 3 passes keep the jobs short.
        "block": (st.integers(8, 32), st.integers(-2, 2) | st.integers(257, 400)),
        "overlap": (st.none() | st.integers(1, 3), st.integers(-1, 0) | st.integers(20, 99)),
        "alpha": (
            st.none() | st.floats(0, 1),
            st.floats(-1, -0.001) | st.floats(1.001, 3) | st.just(float("nan")),
        ),
        "iterations": (st.integers(1, 3), st.integers(-1, 0) | st.integers(9, 12)),
        "correspondence": (
            st.sampled_from(["luminance", "blurred", "orientation"]),
            st.sampled_from(["custom", "LUMINANCE", ""]),
        ),
        "sigma": (st.floats(0.1, 8), st.floats(-1, 0.099) | st.floats(64.01, 100)),
        "remap": (st.booleans(), st.sampled_from([0, 1, "yes", None])),
        "mode": (st.sampled_from(["cut", "overlap"]), st.sampled_from(["random", "CUT"])),
        "seed": (st.integers(0, 2**64 - 1), st.just(-1) | st.just(2**64)),
        "tolerance": (st.floats(0, 10), st.floats(-1, -0.001)),
        "min_candidates": (st.integers(1, 20), st.integers(-1, 0)),
    }
    options: dict[str, Any] = {}
    for key, (valid, invalid) in optional.items():
        if draw(st.booleans()):
            options[key] = pick(valid, invalid)
    if draw(st.integers(0, 19)) == 7:
        options["width"] = 64  # not a transfer option: the target sets the size
    return options


@st.composite
def target_strategy(draw: st.DrawFn) -> tuple[bytes, int, int]:
    """A PNG crop of a test texture, 1..64 pixels a side: (bytes, width, height)."""
    name = draw(st.sampled_from(TEXTURE_NAMES))
    image = np.asarray(Image.open(io.BytesIO(texture(name))))
    width, height = draw(st.integers(1, 64)), draw(st.integers(1, 64))
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image[:height, :width])).save(buffer, format="PNG")
    return buffer.getvalue(), width, height


def test_generated_transfer_options_on_real_images(server: Server) -> None:
    seen: list[int] = []
    with server.client() as client:

        @settings(PROPERTY_SETTINGS, max_examples=30)
        @given(
            options=transfer_options_strategy(),
            name=st.sampled_from(TEXTURE_NAMES),
            target=target_strategy(),
        )
        def run(options: dict[str, Any], name: str, target: tuple[bytes, int, int]) -> None:
            data, width, height = target
            response = client.post(
                "/transfer",
                params={"wait": 0},
                **transfer_request(options, tex=name, target=data),
            )
            codes = ("invalid_parameter", "invalid_options")
            result = check_generated_answer(client, response, seen, codes, "transfer")
            if result is not None:
                assert png_image(result.content).size == (width, height)

        run()
    assert_not_vacuous(seen)


def test_openapi_document_is_served(server: Server) -> None:
    response = httpx.get(server.url + "/openapi.json")
    assert response.status_code == 200
    document = response.json()
    assert document["openapi"].startswith("3.")
    options = document["components"]["schemas"]["SynthesizeOptions"]
    assert {"width", "height"} <= set(options["required"])
    assert options.get("additionalProperties") is False
    transfer = document["components"]["schemas"]["TransferOptions"]
    assert transfer.get("additionalProperties") is False
    assert not transfer.get("required")  # every transfer option has a default
    assert {"width", "height"}.isdisjoint(transfer["properties"])
    assert transfer["properties"]["correspondence"]["enum"] == [
        "luminance",
        "blurred",
        "orientation",
    ]
    assert transfer["properties"]["remap"]["type"] == "boolean"


@st.composite
def wang_options_strategy(draw: st.DrawFn) -> dict[str, Any]:
    """Wang tile options, mostly valid (small sets, so that the jobs are short), with a
    sprinkle of invalid values (see above)."""

    def pick(valid: st.SearchStrategy[Any], invalid: st.SearchStrategy[Any]) -> Any:
        return draw(invalid) if draw(st.integers(0, 9)) == 7 else draw(valid)

    options: dict[str, Any] = {
        "colors": pick(st.integers(2, 3), st.integers(-1, 1) | st.integers(5, 9)),
        "tile": pick(st.integers(8, 24).map(lambda n: 2 * n), st.sampled_from([17, 33, 8, 0])),
    }
    optional = {
        "block": (st.integers(8, 24), st.integers(-2, 2) | st.integers(65, 400)),
        "overlap": (st.none() | st.integers(1, 3), st.integers(-1, 0) | st.integers(20, 99)),
        "blend": (st.sampled_from(["none", "poisson"]), st.sampled_from(["POISSON", ""])),
        "transforms": (
            st.sampled_from(["none", "flips", "rotations", "all", "rot90,flip_x"]),
            st.sampled_from(["spin", "rot45", ""]),
        ),
        "seed": (st.integers(0, 2**64 - 1), st.just(-1) | st.just(2**64)),
        "error": (st.sampled_from(["rgb", "luminance"]), st.sampled_from(["RGB", "hsv"])),
        "weights": (st.just([1.5]), st.sampled_from([[0], [1, 1], [], [-1]])),
    }
    for key, (valid, invalid) in optional.items():
        if draw(st.booleans()):
            options[key] = pick(valid, invalid)
    if draw(st.integers(0, 19)) == 7:
        options["width"] = 64  # not a Wang tile option
    return options


def test_generated_wang_options_on_real_textures(server: Server) -> None:
    seen: list[int] = []
    with server.client() as client:

        @settings(PROPERTY_SETTINGS, max_examples=30)
        @given(options=wang_options_strategy(), name=st.sampled_from(TEXTURE_NAMES))
        def run(options: dict[str, Any], name: str) -> None:
            image = np.asarray(Image.open(io.BytesIO(texture(name))))[:64, :64]
            buffer = io.BytesIO()
            Image.fromarray(np.ascontiguousarray(image)).save(buffer, format="PNG")
            response = client.post(
                "/wang-tiles",
                params={"wait": 0},
                files=[("texture", ("t.png", buffer.getvalue(), "image/png"))],
                data={"options": json.dumps(options)},
            )
            codes = ("invalid_parameter", "invalid_options")
            result = check_generated_answer(client, response, seen, codes, "wang_tiles")
            if result is not None:
                side = options["colors"] ** 2 * options["tile"]
                assert png_image(result.content).size == (side, side)

        run()
    assert_not_vacuous(seen)
