"""Shared fixtures: the test textures, loaded once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

DATA = Path(__file__).resolve().parent / "data"


def load(name: str) -> np.ndarray:
    # Tests read fixtures with Pillow directly so that io.py is tested, not trusted.
    return np.asarray(Image.open(DATA / name))


@pytest.fixture(scope="session")
def gravel() -> np.ndarray:
    return load("gravel.png")


@pytest.fixture(scope="session")
def brick() -> np.ndarray:
    return load("brick.png")


@pytest.fixture(scope="session")
def hubble() -> np.ndarray:
    return load("hubble.png")


@pytest.fixture(scope="session")
def wood() -> np.ndarray:
    return load("wood.png")
