"""End-to-end tests of the web page's texture matting (``POST /matte``) in headless Chromium.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright, and what the page shows checked against
what the service answers over plain HTTP for the same files and options. The target is a shaded
sphere drawn here; the layers are ``brick.png`` (gray) and ``cloud_rgba.png`` (alpha).
"""

from __future__ import annotations

import base64
import io
import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest
import test_web_page
from PIL import Image
from service_helpers import DATA, Server, lit_sphere, png_image
from test_web_page import GRAVEL, UNLABELLED_JS, WebPage

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
open_page = test_web_page.open_page

if TYPE_CHECKING:
    from playwright.sync_api import Request

pytestmark = pytest.mark.browser

MATTE = "Lay on a surface (matting)"  # the operation's radio
SIZE = 160  # the target's side
BRICK = DATA / "brick.png"  # 256 x 256, gray
CLOUD = DATA / "cloud_rgba.png"  # 192 x 192, RGBA
LAYERS = (BRICK, CLOUD)
OPTIONS = {"block": 32, "seed": 3, "clusters": 6, "backend": "fft"}


# --- the images -------------------------------------------------------------------------------


@dataclass
class Sphere:
    """A Lambertian sphere lit from (1, 1, 2): the target, its silhouette and a wrong one."""

    target: Path
    silhouette: Path
    half_silhouette: Path  # SIZE x SIZE / 2: not the target's size


def _save(image: np.ndarray, path: Path) -> Path:
    Image.fromarray(image).save(path)
    return path


@pytest.fixture
def sphere(tmp_path: Path) -> Sphere:
    shade, mask = lit_sphere(SIZE)
    return Sphere(
        target=_save(shade, tmp_path / "sphere.png"),
        silhouette=_save(mask, tmp_path / "sphere-mask.png"),
        half_silhouette=_save(mask[: SIZE // 2], tmp_path / "half-mask.png"),
    )


def matte_over_http(
    server: Server,
    sphere: Sphere,
    options: dict[str, Any],
    layers: tuple[Path, ...] = LAYERS,
    silhouette: Path | None = None,
) -> httpx.Response:
    """``POST /matte?wait=60`` of the files the page was given, as plain HTTP."""
    parts = [("target", sphere.target), ("silhouette", silhouette or sphere.silhouette)]
    parts += [("layer", layer) for layer in layers]
    files = [(name, (path.name, path.read_bytes(), "image/png")) for name, path in parts]
    with server.client() as client:
        return client.post(
            "/matte", params={"wait": 60}, files=files, data={"options": json.dumps(options)}
        )


def choose_matte(
    web: WebPage,
    sphere: Sphere,
    *,
    silhouette: Path | None = None,
    layers: tuple[Path, ...] = LAYERS,
    options: dict[str, Any] | None = None,
) -> None:
    """Pick the matting, its target, silhouette (unless None) and layers, and ``options``."""
    web.operation(MATTE)
    web.soon("#silhouette").to_be_visible()
    web.upload("#target", sphere.target)
    if silhouette is not None:
        web.upload("#silhouette", silhouette)
    web.upload("#layers", *layers)
    web.soon("#layers-order > li").to_have_count(len(layers))
    web.options(**(OPTIONS if options is None else options))


def matte_posts(web: WebPage) -> list[str]:
    """The URLs of the ``POST /matte`` requests the page sends from now on."""
    posts: list[str] = []

    def on_request(request: Request) -> None:
        if request.method == "POST" and "/matte" in request.url:
            posts.append(request.url)

    web.page.on("request", on_request)
    return posts


def job(server: Server, job_id: str) -> dict[str, Any]:
    with server.client() as client:
        response = client.get(f"/jobs/{job_id}")
    assert response.status_code == 200, response.text[:300]
    status: dict[str, Any] = response.json()
    return status


# --- tests --------------------------------------------------------------------------------------


def test_matte_result_and_downloads_are_the_services(
    server: Server, open_page: Callable[..., WebPage], sphere: Sphere
) -> None:
    """Target, silhouette and two layers: the page's PNG is the job's result and the same bytes
    as a plain POST /matte of the same files and options; normals and clusters download."""
    web = open_page(server)
    choose_matte(web, sphere, silhouette=sphere.silhouette, options={})
    # Block presets are relative to the first layer (brick, 256 x 256): Fine is 256 / 8.
    fine = web.page.get_by_role("button", name=re.compile(r"^Fine"))
    web.soon(fine).to_contain_text("32 px")
    fine.click()
    web.options(**{k: v for k, v in OPTIONS.items() if k != "block"})
    options = web.request_options()
    assert options == OPTIONS, options

    job_id = web.run()
    web.wait_image("#result-image", (SIZE, SIZE))
    status = job(server, job_id)
    assert (status["operation"], status["status"]) == ("matte", "done"), status
    assert status["companions"] == ["normals", "clusters"], status

    png = web.download("#download-png")
    assert png_image(png).size == (SIZE, SIZE)
    with server.client() as client:
        stored = client.get(f"/jobs/{job_id}/result")
        assert stored.status_code == 200, stored.text[:300]
        assert png == stored.content, "the download is not the job's result"
        companions = {
            name: client.get(f"/jobs/{job_id}/result/{name}") for name in status["companions"]
        }
    again = matte_over_http(server, sphere, options)
    assert again.status_code == 200, again.text[:300]
    assert png == again.content, "the page's result differs from the service's for its options"

    for name, stored in companions.items():
        assert stored.status_code == 200, (name, stored.text[:300])
        link = f'a.download-companion[data-companion="{name}"]'
        web.soon(link).to_contain_text(name)
        data = web.download(link)
        assert png_image(data).size == (SIZE, SIZE), name
        assert data == stored.content, f"the {name} download is not the job's"
    web.console.assert_clean()


def test_matte_result_has_no_seams_or_layout_but_its_figures(
    server: Server, open_page: Callable[..., WebPage], sphere: Sphere
) -> None:
    """The seam toggle is off with a reason, no layout download, the job's light, clusters and
    patches shown, the target beside the result; a synthesis afterwards has its seams again."""
    web = open_page(server)
    choose_matte(web, sphere, silhouette=sphere.silhouette)
    job_id = web.run()
    web.wait_image("#result-image", (SIZE, SIZE))
    web.soon("#downloads").to_be_visible()

    web.soon("#seams").to_be_disabled()
    web.soon("#seams-info").to_contain_text("no block seams")
    web.soon("#layout-item").to_be_hidden()
    web.soon("#seam-overlay").to_be_hidden()

    stats = job(server, job_id)["stats"]
    # Each figure's value, then (in .meaning) what it means in a sentence.
    figures = dict(
        zip(
            web("#stats dt").all_text_contents(),
            web("#stats dd").evaluate_all("(dds) => dds.map((d) => d.firstChild.textContent)"),
            strict=True,
        )
    )
    shown_light = [float(v) for v in figures["light (x, y, z)"].split(",")]
    assert np.allclose(shown_light, stats["light"], atol=1e-3), (figures, stats)
    assert figures["surface patches"] == str(stats["clusters"]), figures
    assert figures["connected patches"] == str(stats["patches"]), figures
    assert figures["layer size"] == "{} \u00d7 {}".format(*stats["layer_size"]), figures
    assert web("#stats dd .meaning").count() >= 6

    web.page.get_by_role("radio", name="Side by side", exact=True).check()
    web.soon("#input-image").to_be_visible()
    web.wait_image("#input-image", (SIZE, SIZE))  # the target, not a layer
    web.soon("#input-caption").to_have_text("Target")

    # The synthesis after it has a layout and seams again.
    web.page.get_by_role("radio", name="Result", exact=True).check()
    web.operation("Synthesize")
    web.soon("#texture").to_be_visible()
    web.soon("#silhouette").to_be_hidden()
    web.upload("#texture", GRAVEL)
    web.options(width=120, height=100, block=32, seed=3)
    web.run()
    web.wait_image("#result-image", (120, 100))
    web.soon("#seams").to_be_enabled()
    web.soon("#layout-item").to_be_visible()
    web.soon("#input-caption").to_have_text("Input")
    web.console.assert_clean()


def test_missing_or_wrong_size_silhouette(
    server: Server, open_page: Callable[..., WebPage], sphere: Sphere
) -> None:
    """No silhouette: the page says so and sends nothing. One of the wrong size: the service's
    422 detail is shown. The page then still runs a good matting."""
    refused = matte_over_http(server, sphere, OPTIONS, silhouette=sphere.half_silhouette)
    assert refused.status_code == 422, refused.text[:300]
    detail = refused.json()["detail"]
    assert "silhouette" in detail, detail

    web = open_page(server)
    posts = matte_posts(web)
    choose_matte(web, sphere)
    web("#run").click()
    web.soon("#error").to_be_visible()
    web.soon("#error").to_contain_text("choose a silhouette")
    web.soon("#silhouette").to_be_focused()
    web.soon("#run").to_be_enabled()
    assert posts == [], posts

    web.upload("#silhouette", sphere.half_silhouette)
    web.soon("#silhouette-info").to_contain_text(f"not the target's {SIZE} \u00d7 {SIZE}")
    web.start()
    web.wait_final()
    web.soon("#error").to_contain_text(detail)
    web.soon("#error").to_contain_text("422")
    assert len(posts) == 1, posts

    web.upload("#silhouette", sphere.silhouette)
    web.soon("#silhouette-info").to_have_text(
        f"{sphere.silhouette.name}: {SIZE} \u00d7 {SIZE} pixels, 8-bit grey PNG"
    )
    web.run()
    web.wait_image("#result-image", (SIZE, SIZE))
    web.soon("#error").to_be_hidden()
    web.console.assert_clean(http_errors=True)


def test_matte_controls_are_labelled_and_in_order(
    server: Server, open_page: Callable[..., WebPage], sphere: Sphere
) -> None:
    """The matting's inputs and options have labels; the texture box gives way to its own;
    the layers show in their order, can be reordered by keyboard, and run in that order."""
    web = open_page(server)
    assert web("input[type=radio][name=operation]").count() == 7
    web.operation(MATTE)
    web.soon("#operation-hint").to_contain_text("surface")
    for selector in ("#target", "#silhouette", "#layers", "#normals"):
        web.soon(selector).to_be_visible()
    for selector in ("#texture", "#source-mask", "#companions"):
        web.soon(selector).to_be_hidden()
    for label, selector in (
        ("Target", "#target"),
        ("Silhouette", "#silhouette"),
        ("Layers", "#layers"),
        ("Normal map (optional)", "#normals"),
    ):
        assert web.page.get_by_label(label, exact=True).get_attribute("id") == selector[1:]
    assert web("#layers").evaluate("e => e.multiple")
    schemas = httpx.get(server.url + "/openapi.json", timeout=30).json()["components"]["schemas"]
    for name in schemas["MatteOptions"]["properties"]:
        web.soon(f"#opt-{name}").to_have_count(1)
    unlabelled = web.page.evaluate(UNLABELLED_JS)
    assert unlabelled == [], f"controls without an accessible label: {unlabelled}"
    web.soon("#opt-light").to_have_attribute("placeholder", re.compile("x, y, z"))

    # Dropped on their box, two layers show bottom first; the keyboard moves the top one down.
    web.upload("#target", sphere.target)
    web.upload("#silhouette", sphere.silhouette)
    dropped = web.page.evaluate_handle(
        """(files) => {
          const transfer = new DataTransfer();
          for (const [name, b64] of files) {
            const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
            transfer.items.add(new File([bytes], name, {type: 'image/png'}));
          }
          return transfer;
        }""",
        [[path.name, base64.b64encode(path.read_bytes()).decode()] for path in LAYERS],
    )
    web('.drop[data-input="layers"]').dispatch_event("drop", {"dataTransfer": dropped})
    items = web("#layers-order > li")
    web.soon(items).to_have_text([re.compile(r"^brick\.png.*bottom"), re.compile(r"^cloud")])
    raise_cloud = web.page.get_by_role("button", name="Move cloud_rgba.png earlier")
    raise_cloud.focus()
    web.page.keyboard.press("Enter")
    web.soon(items).to_have_text([re.compile(r"^cloud_rgba\.png.*bottom"), re.compile(r"^brick")])
    web.soon(web.page.get_by_role("button", name="Move cloud_rgba.png later")).to_be_focused()
    assert web("#layers").evaluate("e => [...e.files].map((f) => f.name)") == [
        "cloud_rgba.png",
        "brick.png",
    ]
    # The presets follow the first layer: cloud is 192 x 192, Fine is 24.
    web.soon(web.page.get_by_role("button", name=re.compile(r"^Fine"))).to_contain_text("24 px")

    web.options(**OPTIONS)
    web.run()
    web.wait_image("#result-image", (SIZE, SIZE))
    png = web.download("#download-png")
    reordered = matte_over_http(server, sphere, OPTIONS, layers=(CLOUD, BRICK))
    assert png == reordered.content, "the page did not send the layers in the order it shows"
    assert png != matte_over_http(server, sphere, OPTIONS).content, "order makes no difference"

    web.page.get_by_role("button", name="Remove cloud_rgba.png").click()
    web.soon(items).to_have_text([re.compile(r"^brick\.png")])
    web.console.assert_clean()


def test_light_is_sent_as_a_direction_or_refused(
    server: Server, open_page: Callable[..., WebPage], sphere: Sphere
) -> None:
    """A light of "1, 1, 2" is sent as [1, 1, 2] and the job uses it (normalized); "1, 1" is
    refused on the page with a message naming the field, and no request goes out."""
    web = open_page(server)
    posts = matte_posts(web)
    choose_matte(web, sphere, silhouette=sphere.silhouette)
    assert "light" not in web.request_options()  # empty: estimated by the service

    web.option("light", "1, 1")
    web.soon("#request-json").to_contain_text("light: give 3 numbers")
    web("#run").click()
    web.soon("#error").to_be_visible()
    web.soon("#error").to_contain_text('light: give 3 numbers as "x, y, z"')
    web.soon("#opt-light").to_have_attribute("aria-invalid", "true")
    web.soon("#opt-light").to_be_focused()
    web.soon("#run").to_be_enabled()
    assert posts == [], posts

    web.option("light", "1, 1, 2")
    assert web.request_options()["light"] == [1, 1, 2]
    web.soon("#opt-light").not_to_have_attribute("aria-invalid", "true")
    job_id = web.run()
    web.soon("#error").to_be_hidden()
    assert len(posts) == 1, posts
    light = job(server, job_id)["stats"]["light"]
    assert np.allclose(light, np.array([1.0, 1.0, 2.0]) / np.sqrt(6.0)), light
    web.console.assert_clean()


def test_transparent_result_shows_the_checkerboard(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    """A synthesis of an RGBA texture: its clear pixels show the stage's checkerboard (two
    colours), not one flat background."""
    web = open_page(server)
    web.upload("#texture", CLOUD)
    web.options(width=160, height=120, block=32, seed=2)
    job_id = web.run()
    web.wait_image("#result-image", (160, 120))
    web("#zoom").fill("100")
    web.soon("#zoom-value").to_have_text("100 %")
    with server.client() as client:
        result = np.asarray(png_image(client.get(f"/jobs/{job_id}/result").content))
    assert result.shape == (120, 160, 4), result.shape
    clear = result[..., 3] == 0
    assert clear.mean() > 0.1, clear.mean()

    # The picture may sit at a fractional offset: compare away from the clear areas' edges.
    inner = clear.copy()
    inner[1:] &= clear[:-1]
    inner[:-1] &= clear[1:]
    inner[:, 1:] &= clear[:, :-1]
    inner[:, :-1] &= clear[:, 1:]
    shot = np.asarray(Image.open(io.BytesIO(web("#result-image").screenshot())).convert("RGB"))
    assert abs(shot.shape[0] - 120) <= 1 and abs(shot.shape[1] - 160) <= 1, shot.shape
    shot = shot[:120, :160]
    colours, counts = np.unique(shot[inner].reshape(-1, 3), axis=0, return_counts=True)
    main = colours[counts > 0.1 * inner.sum()]
    assert len(main) == 2, f"behind the clear pixels: {colours.tolist()} x {counts.tolist()}"
    web.console.assert_clean()
