"""End-to-end tests of the web page's image boxes in headless Chromium: what was chosen shown
as thumbnails with its size, bit depth and channels (read from the file's own header), a file
dropped on any box, and an image pasted from the clipboard.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright. The files are made here with the depths
and channels each check needs (a 16-bit RGBA PNG, a grey one, a JPEG).
"""

from __future__ import annotations

import base64
import io
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import test_web_page
from PIL import Image
from service_helpers import DATA, Server
from test_web_page import UNLABELLED_JS, WebPage

from quilting.io import encode_png

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
open_page = test_web_page.open_page

pytestmark = pytest.mark.browser

GRAVEL = DATA / "gravel.png"  # 256 x 256, 8-bit grey
CAMERA = DATA / "target_camera.png"  # 256 x 256

#: Makes a DataTransfer holding one file (bytes from base64) in the page; its handle.
TRANSFER_JS = """([b64, name, type]) => {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  const transfer = new DataTransfer();
  transfer.items.add(new File([bytes], name, {type}));
  return transfer;
}"""

#: Pastes one file (bytes from base64) on the focused element, as Ctrl+V of a copied image.
PASTE_JS = """([b64, name, type]) => {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  const data = new DataTransfer();
  data.items.add(new File([bytes], name, {type}));
  const event = new ClipboardEvent('paste', {clipboardData: data, bubbles: true, cancelable: true});
  (document.activeElement || document.body).dispatchEvent(event);
  return event.defaultPrevented;
}"""


def sixteen_bit_rgba(path: Path, width: int = 40, height: int = 24) -> Path:
    """A 16-bit RGBA PNG of ``width`` x ``height``: a ramp no 8-bit file could hold."""
    ramp = np.linspace(0, 65535, width * height * 4).astype(np.uint16)
    path.write_bytes(encode_png(ramp.reshape(height, width, 4)))
    return path


def grey_png(path: Path, width: int = 30, height: int = 20) -> Path:
    Image.fromarray(np.full((height, width), 128, np.uint8)).save(path)
    return path


def jpeg(path: Path, width: int = 50, height: int = 34) -> Path:
    buffer = io.BytesIO()
    Image.fromarray(np.full((height, width, 3), 90, np.uint8)).save(buffer, format="JPEG")
    path.write_bytes(buffer.getvalue())
    return path


def thumbs_loaded(web: WebPage, selector: str, count: int) -> list[int]:
    """Wait until ``selector`` holds ``count`` thumbnails, each a decoded picture; their
    natural widths."""
    web.soon(f"{selector} img.thumb").to_have_count(count)
    web.page.wait_for_function(
        """(s) => [...document.querySelectorAll(s + ' img.thumb')]
          .every((i) => i.complete && i.naturalWidth > 0)""",
        arg=selector,
        timeout=test_web_page.UI_S * 1000,
    )
    widths: list[int] = web(f"{selector} img.thumb").evaluate_all(
        "(images) => images.map((i) => i.naturalWidth)"
    )
    return widths


def file_names(web: WebPage, input_id: str) -> list[str]:
    names: list[str] = web(f"#{input_id}").evaluate("(e) => [...e.files].map((f) => f.name)")
    return names


def test_every_chosen_image_shows_a_thumbnail_with_its_depth(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """The texture, target, silhouette, normal map, layers and companions each show their
    thumbnail, size, bit depth and channels as the file's header says (16-bit RGBA, grey,
    JPEG): what the service will read, not the 8 bits the browser decodes to."""
    deep = sixteen_bit_rgba(tmp_path / "deep.png")
    grey = grey_png(tmp_path / "grey.png")
    photo = jpeg(tmp_path / "photo.jpg")
    web = open_page(server)
    web.upload("#texture", deep)
    assert thumbs_loaded(web, "#textures-order", 1) == [40]
    web.soon("#textures-order .texture-name").to_have_text(
        "deep.png (40 \u00d7 24, 16-bit RGBA PNG)"
    )
    web.soon("#texture-info").to_have_text("deep.png: 40 \u00d7 24 pixels, 16-bit RGBA PNG")
    web.upload("#companions", grey, photo)
    assert thumbs_loaded(web, "#companions-thumbs", 2) == [30, 50]
    assert web("#companions-thumbs .input-name").all_text_contents() == [
        "grey.png: 30 \u00d7 20 pixels, 8-bit grey PNG",
        "photo.jpg: 50 \u00d7 34 pixels, 8-bit RGB JPEG",
    ]

    web.operation("Lay on a surface (matting)")
    web.upload("#target", CAMERA)
    web.upload("#silhouette", grey)
    web.upload("#layers", GRAVEL, deep)
    assert thumbs_loaded(web, "#target-thumbs", 1) == [256]
    web.soon("#target-thumbs .input-name").to_have_text(
        "target_camera.png: 256 \u00d7 256 pixels, 8-bit grey PNG"
    )
    assert thumbs_loaded(web, "#silhouette-thumbs", 1) == [30]
    assert thumbs_loaded(web, "#layers-order", 2) == [256, 40]
    names = web("#layers-order .layer-name").all_text_contents()
    assert names[0].startswith("gravel.png (256 \u00d7 256, 8-bit grey PNG"), names
    assert names[1].startswith("deep.png (40 \u00d7 24, 16-bit RGBA PNG"), names
    # A silhouette of another size than the target's is still said so beside its size.
    web.soon("#silhouette-info").to_contain_text("not the target's 256 \u00d7 256")
    # Taking a file out of its box takes its thumbnail away.
    web("#target").set_input_files([])
    web.soon("#target-thumbs").to_be_hidden()
    assert web.page.evaluate(UNLABELLED_JS) == []
    web.console.assert_clean()


def test_a_file_dropped_on_each_box_goes_into_it(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    """Every image box shown for a transfer, a matting and a fill takes a dropped file into
    its own input (and only there), and shows it."""
    web = open_page(server)
    dropped = web.page.evaluate_handle(
        TRANSFER_JS, [base64.b64encode(GRAVEL.read_bytes()).decode(), "gravel.png", "image/png"]
    )
    for operation in ("Transfer", "Lay on a surface (matting)", "Fill a hole"):
        web.operation(operation)
        boxes = web(".drop[data-input]")
        shown = [
            boxes.nth(i).get_attribute("data-input")
            for i in range(boxes.count())
            if boxes.nth(i).is_visible()
        ]
        assert len(shown) >= 3, (operation, shown)
        for input_id in shown:
            assert input_id
            web(f"#{input_id}").set_input_files([])
            box = web(f'.drop[data-input="{input_id}"]')
            box.dispatch_event("drop", {"dataTransfer": dropped})
            assert file_names(web, input_id) == ["gravel.png"], (operation, input_id)
            if input_id == "texture":
                web.soon("#texture-info").to_contain_text("256 \u00d7 256 pixels, 8-bit grey PNG")
            elif input_id == "layers":
                web.soon("#layers-order img.thumb").to_have_count(1)
            else:
                web.soon(f"#{input_id}-thumbs img.thumb").to_have_count(1)
    web.console.assert_clean()


def test_paste_an_image_into_the_box_in_focus_or_the_first_empty(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """Ctrl+V of a copied image: into the box holding the focus; with the focus elsewhere,
    into the first shown box with nothing chosen; a box of several gets it added. The page
    says where it went, and a copied screenshot ("image.png") is named "pasted.png"."""
    web = open_page(server)
    web.operation("Transfer")
    png = base64.b64encode(GRAVEL.read_bytes()).decode()
    # Nothing focused: the first empty box shown, the texture's.
    web.page.evaluate("() => document.activeElement?.blur()")
    assert web.page.evaluate(PASTE_JS, [png, "image.png", "image/png"]) is True
    assert file_names(web, "texture") == ["pasted.png"]
    web.soon("#status").to_have_text("Pasted pasted.png into Texture.")
    web.soon("#texture-info").to_contain_text("pasted.png: 256 \u00d7 256 pixels")
    # The focus in the target's box: the target.
    web("#target").focus()
    camera = base64.b64encode(CAMERA.read_bytes()).decode()
    assert web.page.evaluate(PASTE_JS, [camera, "camera.png", "image/png"]) is True
    assert file_names(web, "target") == ["camera.png"]
    assert file_names(web, "texture") == ["pasted.png"], "the texture changed too"
    web.soon("#target-thumbs img.thumb").to_have_count(1)
    # A box of several: the pasted image is added to those chosen.
    web("#companions").set_input_files([GRAVEL])
    web("#companions").focus()
    assert web.page.evaluate(PASTE_JS, [png, "height.png", "image/png"]) is True
    assert file_names(web, "companions") == ["gravel.png", "height.png"]
    web.soon("#companions-thumbs img.thumb").to_have_count(2)
    # Text pasted into a text field is left to the field.
    web.option("seed", "")
    web("#opt-seed").focus()
    text = web.page.evaluate(
        """() => {
          const data = new DataTransfer();
          data.setData('text/plain', '42');
          const event = new ClipboardEvent('paste', {clipboardData: data, bubbles: true,
            cancelable: true});
          document.activeElement.dispatchEvent(event);
          return event.defaultPrevented;
        }"""
    )
    assert text is False
    web.console.assert_clean()


def test_the_header_reader_knows_each_kind_of_file(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """The depth and channels come from the file's own header whatever comes before the frame
    (a progressive JPEG after its EXIF segment, a CMYK JPEG) and whatever the PNG holds (a
    palette, grey with alpha, 16-bit grey); a file that is neither says so."""
    pixels = np.random.default_rng(3).integers(0, 256, (18, 26, 3), dtype=np.uint8)
    picture = Image.fromarray(pixels)
    exif = Image.Exif()
    exif[0x010E] = "a texture photographed on a phone"  # ImageDescription: an APP1 segment
    made = {
        "exif.jpg": lambda p: picture.save(p, format="JPEG", progressive=True, exif=exif.tobytes()),
        "cmyk.jpg": lambda p: picture.convert("CMYK").save(p, format="JPEG"),
        "palette.png": lambda p: picture.convert("P").save(p),
        "grey_alpha.png": lambda p: picture.convert("LA").save(p),
        "grey16.png": lambda p: p.write_bytes(encode_png(np.full((18, 26), 40000, np.uint16))),
    }
    paths = []
    for name, write in made.items():
        write(tmp_path / name)
        paths.append(tmp_path / name)
    notes = tmp_path / "notes.png"
    notes.write_text("not a picture at all")
    web = open_page(server)
    web.upload("#companions", *paths, notes)
    web.soon("#companions-thumbs .input-name").to_have_count(len(paths) + 1)
    assert web("#companions-thumbs .input-name").all_text_contents() == [
        "exif.jpg: 26 \u00d7 18 pixels, 8-bit RGB JPEG",
        "cmyk.jpg: 26 \u00d7 18 pixels, 8-bit CMYK JPEG",
        "palette.png: 26 \u00d7 18 pixels, 8-bit palette PNG",
        "grey_alpha.png: 26 \u00d7 18 pixels, 8-bit grey + alpha PNG",
        "grey16.png: 26 \u00d7 18 pixels, 16-bit grey PNG",
        "notes.png: not an image this browser can show",
    ]
    web.console.assert_clean()
