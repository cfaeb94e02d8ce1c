"""Shared fixtures: the test textures, loaded once; the GL context, probed once."""

from __future__ import annotations

import os
from collections.abc import Generator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from quilting.core.errors import BackendError
from quilting.io import write_image

DATA = Path(__file__).resolve().parent / "data"


def load(name: str) -> np.ndarray:
    # Tests read fixtures with Pillow directly so that io.py is tested, not trusted.
    return np.asarray(Image.open(DATA / name))


def _image_fixture(name: str, file: str, doc: str) -> Any:
    """A session fixture ``name``: ``tests/data/<file>`` read once with :func:`load`."""

    def image() -> np.ndarray:
        return load(file)

    image.__doc__ = doc
    return pytest.fixture(scope="session", name=name)(image)


gravel = _image_fixture("gravel", "gravel.png", "256x256 gray gravel.")
brick = _image_fixture("brick", "brick.png", "256x256 gray brick wall.")
hubble = _image_fixture("hubble", "hubble.png", "256x256 RGB Hubble image.")
wood = _image_fixture("wood", "wood.png", "136x136 RGB wood grain.")
camera = _image_fixture(
    "camera", "target_camera.png", 'The 256x256 gray "cameraman" photo: a texture-transfer target.'
)


# --------------------------------------------------------------------------------------------
# GL: tests marked `gl` need an OpenGL 4.3 context (moderngl on EGL). Without one they skip,
# except in CI: `.ci/run` sets QUILTING_REQUIRE_GL=1, and there a GL test that does not run is
# a failure, whichever way it skipped.
# --------------------------------------------------------------------------------------------

REQUIRE_GL_VARIABLE = "QUILTING_REQUIRE_GL"


def gl_required() -> bool:
    """True when a GL test may not skip (``QUILTING_REQUIRE_GL`` set, not ``0``)."""
    return os.environ.get(REQUIRE_GL_VARIABLE, "").strip() not in ("", "0")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        f"gl: needs an OpenGL 4.3 context (moderngl on EGL); with {REQUIRE_GL_VARIABLE} set "
        "a skip is reported as a failure",
    )
    config.addinivalue_line(
        "markers", "browser: drives the web page in headless Chromium (tests/service/browser.py)"
    )


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    report = yield
    # An expected failure (xfail) is reported as skipped too; it ran, so it stays as it is.
    if (
        report.skipped
        and not hasattr(report, "wasxfail")
        and item.get_closest_marker("gl") is not None
        and gl_required()
    ):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else report.longrepr
        report.outcome = "failed"
        report.longrepr = (
            f"a GL test skipped while {REQUIRE_GL_VARIABLE} is set (CI must run every GL "
            f"test): {reason}"
        )
    return report


@pytest.fixture(scope="session")
def gl_info() -> Any:
    """The GL context's :class:`quilting.costs.gl.GLInfo`, probed once per session.

    Skips the test when no context can be made, or fails it when ``QUILTING_REQUIRE_GL`` is
    set. Tests using it should carry the ``gl`` marker.
    """
    try:
        from quilting.costs import gl

        return gl.probe()
    except ImportError as exc:
        reason = f"moderngl is not installed (pip install 'quilting[gl]'): {exc}"
    except BackendError as exc:
        reason = f"no OpenGL context: {exc.message}"
    if gl_required():
        pytest.fail(f"{REQUIRE_GL_VARIABLE} is set but {reason}", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def gl(gl_info: Any) -> Any:
    """The ``quilting.costs.gl`` module, once a context is known to work (see ``gl_info``)."""
    from quilting.costs import gl

    return gl


@pytest.fixture
def sphere_files(tmp_path: Path) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    """A 96² Lambertian sphere lit from (1, 1, 2) and its silhouette, as PNG files (the
    command lines' matte tests)."""
    axis = np.arange(96) - 47.5
    x, y = np.meshgrid(axis, -axis)
    inside = x**2 + y**2 < 38**2
    z = np.sqrt(np.clip(38**2 - x**2 - y**2, 0, None))
    light = np.array([1.0, 1.0, 2.0]) / np.sqrt(6.0)
    shade = np.clip(np.stack([x, y, z], axis=-1) @ light / 38, 0, 1) * 0.8 * inside
    target = np.rint(shade * 255).astype(np.uint8)
    mask = (inside * 255).astype(np.uint8)
    write_image(tmp_path / "target.png", target)
    write_image(tmp_path / "mask.png", mask)
    return tmp_path / "target.png", tmp_path / "mask.png", target, mask
