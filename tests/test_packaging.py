"""The wheel ships what the package loads at run time: the shaders of the gl backend."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_wheel_carries_every_shader(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), str(ROOT)],
        check=True,
        capture_output=True,
        cwd=tmp_path,  # not the checkout: a build must not depend on the working directory
    )
    (wheel,) = tmp_path.glob("quilting-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shaders = sorted(p.name for p in (ROOT / "shaders").glob("*.comp"))
    assert shaders  # the three kernels of the gl backend
    for name in shaders:
        assert f"quilting/shaders/{name}" in names
    assert "quilting/costs/gl.py" in names
