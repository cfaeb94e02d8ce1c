"""The routes behind the browser page: the page's files at / and /web/, and the seams overlay.

Against a real ``quilting serve``; the page itself is tested in a browser by test_web_page.py.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import httpx
import numpy as np
import pytest
from service_helpers import (
    ROOT,
    assert_png,
    assert_problem,
    job_id_of,
    png_image,
    synth,
    wait_for,
)

import quilting

WEB = ROOT / "client" / "web"
SECURED = {"Authorization": "Bearer k1"}


def test_the_page_is_served_at_the_root(client: httpx.Client) -> None:
    response = client.get("/")
    assert response.status_code == 200
    assert response.headers["content-type"] == "text/html; charset=utf-8"
    assert response.content == (WEB / "index.html").read_bytes()
    policy = response.headers["content-security-policy"]
    assert "default-src 'self'" in policy and "script-src 'self'" in policy
    assert response.headers["x-content-type-options"] == "nosniff"


def test_every_file_the_page_references_is_served(client: httpx.Client) -> None:
    """Every /web/ name in index.html and every module import resolves, with its type."""
    html = (WEB / "index.html").read_text()
    names = set(re.findall(r'"/web/([^"]+)"', html))
    scripts = [WEB / name for name in names if name.endswith(".js")]
    for script in scripts:
        names |= set(re.findall(r'from "\./([^"]+)"', script.read_text()))
    assert {"app.js", "style.css", "api.js", "options.js", "viewer.js"} <= names
    types = {".js": "text/javascript", ".css": "text/css"}
    for name in names:
        response = client.get(f"/web/{name}")
        assert response.status_code == 200, name
        assert response.content == (WEB / name).read_bytes()
        assert response.headers["content-type"].startswith(types[Path(name).suffix]), name


@pytest.mark.parametrize("name", ["nope.js", "__init__.py", "..%2Fpyproject.toml"])
def test_only_the_page_files_are_served(client: httpx.Client, name: str) -> None:
    assert_problem(client.get(f"/web/{name}"), 404, "not_found")


def test_the_page_needs_no_key_but_jobs_do(secured_server) -> None:  # type: ignore[no-untyped-def]
    """The page loads without a key (it asks for one); the API behind it still needs it."""
    with secured_server.client() as c:
        assert c.get("/").status_code == 200
        assert c.get("/web/app.js").status_code == 200
        assert c.get("/openapi.json").status_code == 200
        assert_problem(c.get("/jobs/0123/seams"), 401, "unauthorized")


def test_the_page_can_be_turned_off(start_server) -> None:  # type: ignore[no-untyped-def]
    server = start_server("no-page", {"QUILTING_WEB_PAGE": "false", "QUILTING_WORKERS": "1"})
    with server.client() as c:
        assert_problem(c.get("/"), 404, "not_found")
        assert_problem(c.get("/web/app.js"), 404, "not_found")
        assert c.get("/healthz").status_code == 200


def test_the_option_schemas_are_menus_where_values_are_few(client: httpx.Client) -> None:
    """The page builds its form from these: a choice must list its values."""
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    backend = schemas["SynthesizeOptions"]["properties"]["backend"]
    assert backend["enum"] == ["auto", "fft", "gl", "reference"]
    assert schemas["TransferOptions"]["properties"]["backend"]["enum"] == backend["enum"]
    for name in ("SynthesizeOptions", "TransferOptions", "TileOptions"):
        for prop, spec in schemas[name]["properties"].items():
            assert spec.get("description"), (name, prop)


def _done_job(client: httpx.Client, options: dict[str, object], **kwargs: object) -> str:
    response = synth(client, options, wait=30, **kwargs)  # type: ignore[arg-type]
    job_id = job_id_of(response)
    wait_for(client, job_id, headers=kwargs.get("headers"))  # type: ignore[arg-type]
    return job_id


@pytest.mark.parametrize(
    "options",
    [
        {"width": 150, "height": 110, "block": 32, "seed": 4},
        {"width": 130, "height": 130, "block": 32, "seed": 2, "tileable": "both"},
        {"width": 140, "height": 120, "block": 32, "seed": 1, "mode": "walk"},
    ],
)
def test_seams_are_where_the_result_changes_block(
    client: httpx.Client, gravel: np.ndarray, options: dict[str, object]
) -> None:
    """The overlay is opaque exactly on the seams the Python API reports for the same job,
    transparent elsewhere, of the result's size."""
    job_id = _done_job(client, options)
    response = client.get(f"/jobs/{job_id}/seams")
    overlay = np.asarray(assert_png(response, options["width"], options["height"]))  # type: ignore[arg-type]
    assert overlay.shape[2] == 4
    on = overlay[..., 3] == 255
    assert np.all(overlay[..., 3][~on] == 0)
    assert np.all(overlay[on][:, :3] == (255, 0, 0))

    size = (options["height"], options["width"])  # the Python API takes (height, width)
    engine = {k: v for k, v in options.items() if k not in ("width", "height")}
    result = quilting.synthesize(gravel, size, backend="fft", **engine)  # type: ignore[arg-type]
    assert np.array_equal(on, quilting.seam_mask(result.layout))
    # And the layout the service hands out gives the same seams.
    layout = quilting.Layout.from_json(client.get(f"/jobs/{job_id}/layout").content)
    assert np.array_equal(on, quilting.seam_mask(layout))
    assert 0.01 < on.mean() < 0.3


def test_seams_take_a_colour(client: httpx.Client) -> None:
    job_id = _done_job(client, {"width": 100, "height": 90, "block": 30})
    overlay = np.asarray(png_image(client.get(f"/jobs/{job_id}/seams?color=00FF80").content))
    on = overlay[..., 3] == 255
    assert on.any() and np.all(overlay[on][:, :3] == (0, 255, 128))
    for bad in ("red", "12345", "gggggg", "#ff0000"):
        response = client.get(f"/jobs/{job_id}/seams", params={"color": bad})
        assert_problem(response, 422, "invalid_parameter", "color")


def test_seams_of_unknown_or_unfinished_jobs(client: httpx.Client) -> None:
    assert_problem(client.get("/jobs/nope/seams"), 404, "job_not_found")
    response = synth(client, {"width": 2400, "height": 2400, "block": 24}, wait=0)
    job_id = job_id_of(response)
    assert_problem(client.get(f"/jobs/{job_id}/seams"), 409, "job_not_done")
    client.delete(f"/jobs/{job_id}")
    status = wait_for(client, job_id)
    assert status["status"] == "cancelled"
    assert_problem(client.get(f"/jobs/{job_id}/seams"), 409, "job_cancelled")


def test_seams_belong_to_the_key_that_made_the_job(secured_server) -> None:  # type: ignore[no-untyped-def]
    with secured_server.client() as c:
        job_id = _done_job(c, {"width": 80, "height": 80, "block": 24}, headers=SECURED)
        assert_png(c.get(f"/jobs/{job_id}/seams", headers=SECURED), 80, 80)
        other = {"X-API-Key": "k2"}
        assert_problem(c.get(f"/jobs/{job_id}/seams", headers=other), 404, "job_not_found")


def test_layout_download_is_what_the_page_offers(client: httpx.Client) -> None:
    job_id = _done_job(client, {"width": 90, "height": 70, "block": 24})
    layout = json.loads(client.get(f"/jobs/{job_id}/layout").content)
    assert layout["version"] >= 1 and layout["output_shape"] == [70, 90]
