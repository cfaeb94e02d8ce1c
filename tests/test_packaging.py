"""The wheel ships what the package loads at run time: every module of every subpackage, the
shaders of the gl backend, the Redis store's Lua script."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_wheel_carries_every_module_shader_and_script(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), str(ROOT)],
        check=True,
        capture_output=True,
        cwd=tmp_path,  # not the checkout: a build must not depend on the working directory
    )
    (wheel,) = tmp_path.glob("quilting-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shaders = sorted(p.name for p in (ROOT / "shaders").iterdir() if p.suffix in (".comp", ".glsl"))
    assert shaders  # the three kernels of the gl backend and the pieces they include
    for name in shaders:
        assert f"quilting/shaders/{name}" in names
    assert "quilting/costs/gl.py" in names
    # Every module and script of the source tree (a subpackage left out of pyproject's list
    # would install a package that cannot import its kernels).
    package = ROOT / "server" / "quilting"
    shipped = [
        p.relative_to(package.parent).as_posix()
        for pattern in ("*.py", "*.lua")
        for p in package.rglob(pattern)
        if "__pycache__" not in p.parts
    ]
    assert "quilting/core/kernels/seams.py" in shipped
    assert "quilting/service/jobs/jobs.lua" in shipped
    assert sorted(set(shipped) - names) == []
