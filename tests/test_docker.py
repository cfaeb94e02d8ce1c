"""The container files, checked without a Docker engine (there is none in CI).

docker/Dockerfile and docker/Dockerfile.gpu are parsed and held to the layout the README
describes: one install step, docker/install.sh; an unprivileged user; the CPU image serving
HTTP with a health check on /healthz. docker/compose.yaml is loaded and held to the same.
The files an image copies are enough to build the wheel: the test builds it from them alone.
"""

from __future__ import annotations

import http.server
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
import tomllib
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import urlparse

import pytest
import yaml

from quilting.cli import build_parser
from quilting.service.settings import Settings, describe

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"
INSTALL = DOCKER / "install.sh"
COMPOSE = DOCKER / "compose.yaml"
#: Each image and the role of docker/install.sh it installs with.
IMAGES = {"Dockerfile": "cpu", "Dockerfile.gpu": "gpu"}


@dataclass(frozen=True)
class Instruction:
    keyword: str  # upper case: FROM, RUN, COPY...
    args: str  # the rest, continuation lines joined

    def exec_form(self) -> list[str] | None:
        """The JSON array of an exec-form CMD/RUN/HEALTHCHECK CMD, else None."""
        text = self.args
        if self.keyword == "HEALTHCHECK":
            words = text.split()
            while words and words[0].startswith("--"):
                words.pop(0)
            if not words or words[0] != "CMD":
                return None
            text = text[text.index("CMD") + 3 :]
        text = text.strip()
        if not text.startswith("["):
            return None
        value = json.loads(text)
        assert isinstance(value, list) and all(isinstance(v, str) for v in value), text
        return value


def parse_dockerfile(path: Path) -> list[Instruction]:
    """Instructions in order: comments and blank lines dropped, continuation lines joined."""
    instructions: list[Instruction] = []
    pending = ""
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue  # a comment inside a continued instruction is dropped, as Docker does
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        text = pending + line
        pending = ""
        keyword, _, args = text.partition(" ")
        instructions.append(Instruction(keyword.upper(), args.strip()))
    assert not pending, f"{path.name} ends inside a continued line"
    return instructions


def env_of(instructions: list[Instruction]) -> dict[str, str]:
    """The ENV variables an image ends with (``KEY=VALUE`` pairs; ``$PATH`` left as it is)."""
    env: dict[str, str] = {}
    for ins in instructions:
        if ins.keyword == "ENV":
            for pair in shlex.split(ins.args):
                key, sep, value = pair.partition("=")
                assert sep, f"ENV {ins.args!r}: use KEY=VALUE"
                env[key] = value
    return env


def only(instructions: list[Instruction], keyword: str) -> Instruction:
    found = [ins for ins in instructions if ins.keyword == keyword]
    assert len(found) == 1, f"{len(found)} {keyword} instructions, expected one"
    return found[0]


def quilting_env(env: dict[str, Any]) -> dict[str, str]:
    return {key: str(value) for key, value in env.items() if key.startswith("QUILTING_")}


@pytest.fixture(params=sorted(IMAGES))
def image(request: pytest.FixtureRequest) -> tuple[str, list[Instruction]]:
    name = str(request.param)
    return name, parse_dockerfile(DOCKER / name)


# ------------------------------------------------------------------------------------------
# The Dockerfiles
# ------------------------------------------------------------------------------------------


def test_the_install_script_is_the_only_install_step(image: tuple[str, list[Instruction]]) -> None:
    name, instructions = image
    assert instructions[0].keyword == "FROM"
    assert instructions[0].args == "python:3.11-slim-bookworm"
    runs = [ins.args for ins in instructions if ins.keyword == "RUN"]
    assert runs == [f"sh docker/install.sh {IMAGES[name]}"], runs
    # ADD can fetch URLs and unpack archives: only COPY brings files in.
    assert not [ins for ins in instructions if ins.keyword == "ADD"]
    for ins in instructions:
        if ins.keyword not in ("RUN", "COPY"):
            assert not re.search(r"\b(apt-get|apt|pip|curl|wget)\b", ins.args), ins


def test_the_image_runs_as_an_unprivileged_user(image: tuple[str, list[Instruction]]) -> None:
    _, instructions = image
    keywords = [ins.keyword for ins in instructions]
    assert keywords[-1] == "CMD"
    users = [i for i, ins in enumerate(instructions) if ins.keyword == "USER"]
    assert users, "no USER: the image would run as root"
    last = instructions[users[-1]].args
    assert users[-1] > keywords.index("RUN"), "USER before the install step"
    user, _, group = last.partition(":")
    assert user not in ("root", "0") and group not in ("root", "0"), last
    # The uid is the one docker/install.sh creates (by number, so runAsNonRoot can check it).
    uid = re.search(r"^SERVICE_UID=(\d+)$", INSTALL.read_text(), re.MULTILINE)
    assert uid is not None
    assert user == uid.group(1), (user, uid.group(1))


def test_the_image_runs_quilting_from_the_venv(image: tuple[str, list[Instruction]]) -> None:
    name, instructions = image
    env = env_of(instructions)
    venv = env["VENV"]
    # VENV is set before the install step runs, and the venv's bin comes first on PATH.
    run = next(i for i, ins in enumerate(instructions) if ins.keyword == "RUN")
    assert any(ins.keyword == "ENV" and "VENV=" in ins.args for ins in instructions[:run]), (
        "VENV must be set before docker/install.sh runs"
    )
    assert env["PATH"].split(":")[0] == f"{venv}/bin"
    assert env["PATH"].split(":")[1:] == ["$PATH"]
    cmd = only(instructions, "CMD").exec_form()
    assert cmd == (["quilting", "serve"] if name == "Dockerfile" else ["quilting", "worker"])
    # `quilting` is the package's console script, and the command parses.
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert cmd[0] in scripts
    build_parser().parse_args(cmd[1:])
    # Its QUILTING_* variables are valid settings.
    Settings.from_env(quilting_env(env))


def test_the_cpu_image_serves_http_with_a_health_check() -> None:
    instructions = parse_dockerfile(DOCKER / "Dockerfile")
    env = env_of(instructions)
    assert env["QUILTING_HOST"] == "0.0.0.0"  # reachable from outside the container
    assert only(instructions, "EXPOSE").args == "8000"
    check = only(instructions, "HEALTHCHECK").exec_form()
    assert check is not None, "HEALTHCHECK CMD in exec form"
    assert check[0] == f"{env['VENV']}/bin/python", "slim images have no curl: the venv's python"
    assert "/healthz" in " ".join(check)


class _Health(http.server.BaseHTTPRequestHandler):
    def do_GET(self) -> None:
        self.send_response(200 if self.path == "/healthz" else 404)
        self.end_headers()

    def log_message(self, *args: Any) -> None:
        pass


@pytest.fixture
def health_server() -> Iterator[int]:
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Health)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server.server_address[1]
    server.shutdown()
    server.server_close()


def test_the_health_check_passes_on_healthz_and_fails_without_it(health_server: int) -> None:
    check = only(parse_dockerfile(DOCKER / "Dockerfile"), "HEALTHCHECK").exec_form()
    assert check is not None
    command = [sys.executable, *check[1:]]  # this venv's python in place of the image's

    def run(port: int) -> int:
        env = {**os.environ, "QUILTING_PORT": str(port)}
        return subprocess.run(command, env=env, capture_output=True, timeout=30).returncode

    assert run(health_server) == 0
    closed = http.server.HTTPServer(("127.0.0.1", 0), _Health)
    port = closed.server_address[1]
    closed.server_close()  # nothing listens there now
    assert run(port) != 0


def test_the_gpu_image_is_a_gl_worker_with_nvidia_graphics() -> None:
    instructions = parse_dockerfile(DOCKER / "Dockerfile.gpu")
    env = env_of(instructions)
    assert "graphics" in env["NVIDIA_DRIVER_CAPABILITIES"].split(",")  # EGL comes with graphics
    assert env["NVIDIA_VISIBLE_DEVICES"] == "all"
    assert env["QUILTING_BACKEND"] == "gl"
    # EGL loads NVIDIA's vendor file alone, the one docker/install.sh writes: without the driver
    # gl fails, instead of running on the llvmpipe device of Mesa's vendor (libegl1 brings it).
    vendor = re.search(r"^NVIDIA_EGL_VENDOR=(\S+)$", INSTALL.read_text(), re.MULTILINE)
    assert vendor is not None
    assert env["__EGL_VENDOR_LIBRARY_FILENAMES"] == vendor.group(1)
    # A worker serves no HTTP: no port, and no health check that asks for one.
    assert not [ins for ins in instructions if ins.keyword == "EXPOSE"]
    assert only(instructions, "HEALTHCHECK").args == "NONE"


# ------------------------------------------------------------------------------------------
# What the images copy is what `pip install .` needs
# ------------------------------------------------------------------------------------------


def copied(instructions: list[Instruction]) -> dict[str, PurePosixPath]:
    """``{source in the build context: destination}`` of every COPY, WORKDIR applied."""
    workdir = PurePosixPath("/")
    result: dict[str, PurePosixPath] = {}
    for ins in instructions:
        if ins.keyword == "WORKDIR":
            workdir = workdir / ins.args
        elif ins.keyword == "COPY":
            *sources, dest = ins.args.split()
            assert sources and not any(s.startswith("--") for s in sources), ins
            target = workdir / dest
            for source in sources:
                result[source] = (
                    target / PurePosixPath(source).name
                    if len(sources) > 1 or dest.endswith("/")
                    else target
                )
    return result


def needed_by_pip() -> set[str]:
    """The files and folders of the checkout that `pip install .` reads."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    needed = {"pyproject.toml", project["project"]["readme"]}
    needed |= set(project["tool"]["setuptools"]["package-dir"].values())
    return needed


def test_the_copied_files_are_what_pip_install_needs(image: tuple[str, list[Instruction]]) -> None:
    _, instructions = image
    sources = copied(instructions)
    workdir = PurePosixPath("/src")
    for path in needed_by_pip() | {"docker/install.sh"}:
        # Copied itself or inside a copied folder, to the same place under the workdir.
        owner = next(
            (s for s in sources if path == s or path.startswith(s.rstrip("/") + "/")), None
        )
        assert owner is not None, f"{path} is not copied into the image"
        assert sources[owner] / PurePosixPath(path).relative_to(owner) == workdir / path
    for source in sources:
        assert (ROOT / source).exists(), source
    # The install step runs in the folder the files were copied to.
    run = next(i for i, ins in enumerate(instructions) if ins.keyword == "RUN")
    workdirs = [ins.args for ins in instructions[:run] if ins.keyword == "WORKDIR"]
    assert workdirs[-1] == str(workdir)


def test_a_wheel_builds_from_the_copied_files_alone(tmp_path: Path) -> None:
    context = tmp_path / "context"
    for source in copied(parse_dockerfile(DOCKER / "Dockerfile")):
        origin = ROOT / source
        target = context / source
        target.parent.mkdir(parents=True, exist_ok=True)
        if origin.is_dir():
            shutil.copytree(
                origin, target, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info")
            )
        else:
            shutil.copy2(origin, target)
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), "."],
        check=True,
        capture_output=True,
        cwd=context,
    )
    (wheel,) = tmp_path.glob("quilting-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for shader in (ROOT / "shaders").glob("*.comp"):
        assert f"quilting/shaders/{shader.name}" in names
    for page in (ROOT / "client" / "web").iterdir():
        if page.suffix in (".html", ".js", ".css", ".svg"):
            assert f"quilting/web/{page.name}" in names
    assert "quilting/service/jobs/jobs.lua" in names
    assert "quilting/cli.py" in names


def test_the_build_context_keeps_only_what_the_images_copy() -> None:
    patterns = {}
    for name in IMAGES:
        ignore = DOCKER / f"{name}.dockerignore"  # BuildKit reads <Dockerfile>.dockerignore
        lines = [line.strip() for line in ignore.read_text().splitlines()]
        patterns[name] = [line for line in lines if line and not line.startswith("#")]
    cpu, gpu = patterns["Dockerfile"], patterns["Dockerfile.gpu"]
    assert cpu == gpu, "the two images' .dockerignore files differ"
    assert cpu[0] == "*", "an allow-list: everything out, then what the images copy"
    allowed = {p[1:] for p in cpu if p.startswith("!")}
    for name in IMAGES:
        for source in copied(parse_dockerfile(DOCKER / name)):
            assert source.rstrip("/") in allowed, f"{name} copies {source}, which is ignored"
    for heavy in (".venv", ".git", "build"):
        assert heavy not in allowed


# ------------------------------------------------------------------------------------------
# docker/install.sh and CI
# ------------------------------------------------------------------------------------------


def test_the_install_script_is_valid_posix_sh() -> None:
    subprocess.run(["sh", "-n", str(INSTALL)], check=True)
    if shutil.which("dash"):
        subprocess.run(["dash", "-n", str(INSTALL)], check=True)
    text = INSTALL.read_text()
    assert text.startswith("#!/bin/sh\n")
    assert "\nset -eu\n" in text
    for role in ("cpu", "gpu", "ci"):
        assert re.search(rf"^\s+{role}\) role_{role} ;;$", text, re.MULTILINE), role


@pytest.mark.parametrize("args", [[], ["gpus"]])
def test_the_install_script_refuses_an_unknown_role(args: list[str]) -> None:
    done = subprocess.run(["sh", str(INSTALL), *args], capture_output=True, text=True)
    assert done.returncode == 2
    assert "usage: sh docker/install.sh cpu|gpu|ci" in done.stderr


def test_the_install_script_writes_a_valid_nvidia_egl_vendor_file() -> None:
    text = INSTALL.read_text()
    assert "NVIDIA_EGL_VENDOR=/usr/share/glvnd/egl_vendor.d/10_nvidia.json" in text
    literal = re.search(r"vendor='(\{.*?\})'", text, re.DOTALL)
    assert literal is not None
    vendor = json.loads(literal.group(1))
    assert vendor["ICD"]["library_path"] == "libEGL_nvidia.so.0"


def test_the_install_script_uses_apt_quietly_and_without_recommends() -> None:
    for line in INSTALL.read_text().splitlines():
        command = line.strip()
        if command.startswith("apt-get install"):
            assert "-q" in command.split() and "--no-install-recommends" in command, command
        if command.startswith("apt-get update"):
            assert "-q" in command.split(), command


def test_ci_runs_the_install_script() -> None:
    ci = (ROOT / ".ci" / "run").read_text()
    last = ci.strip().splitlines()[-1]
    assert last.startswith("sh docker/install.sh ci && ")
    for variable in ("QUILTING_REQUIRE_GL", "QUILTING_REQUIRE_BROWSER", "QUILTING_REQUIRE_REDIS"):
        assert f"\nexport {variable}=1\n" in ci, variable
    # One install script: the old ones are gone and nothing points at them.
    for old in ("tests/install_mesa.sh", "tests/install_browser.sh"):
        assert not (ROOT / old).exists()
        assert old not in ci and old not in (ROOT / "README.md").read_text()


# ------------------------------------------------------------------------------------------
# docker/compose.yaml
# ------------------------------------------------------------------------------------------


def interpolate(value: str) -> str:
    """Compose's ``${VAR:-default}`` with no variable set: the default."""
    return re.sub(r"\$\{[A-Z0-9_]+:-([^}]*)\}", r"\1", value)


def seconds(duration: str) -> float:
    """A compose duration such as ``40s``, ``1m30s``."""
    units = {"h": 3600.0, "m": 60.0, "s": 1.0, "ms": 0.001}
    parts = re.findall(r"(\d+(?:\.\d+)?)(ms|h|m|s)", duration)
    assert parts and "".join(n + u for n, u in parts) == duration, duration
    return sum(float(n) * units[u] for n, u in parts)


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    loaded = yaml.safe_load(COMPOSE.read_text())
    assert isinstance(loaded, dict)
    return loaded


@pytest.fixture(scope="module")
def services(compose: dict[str, Any]) -> dict[str, dict[str, Any]]:
    found = compose["services"]
    assert isinstance(found, dict)
    return found


def dockerfile_of(service: dict[str, Any]) -> Path:
    build = service["build"]
    context = (COMPOSE.parent / build["context"]).resolve()
    assert context == ROOT, "the build context is the repository root"
    return context / build["dockerfile"]


def test_compose_has_redis_with_a_volume_and_a_health_check(
    compose: dict[str, Any], services: dict[str, dict[str, Any]]
) -> None:
    redis = services["redis"]
    assert redis["image"].startswith("redis:7")
    command = redis["command"]
    assert "--appendonly" in command and command[command.index("--appendonly") + 1] == "yes"
    (volume,) = redis["volumes"]
    name, _, path = volume.partition(":")
    assert path == "/data" and name in compose["volumes"]
    assert redis["healthcheck"]["test"] == ["CMD", "redis-cli", "ping"]


def test_compose_api_and_workers_share_redis(services: dict[str, dict[str, Any]]) -> None:
    assert {"redis", "api", "worker", "gpu-worker"} <= set(services)
    for name in ("api", "worker", "gpu-worker"):
        service = services[name]
        url = urlparse(service["environment"]["QUILTING_QUEUE"])
        assert url.scheme == "redis" and url.hostname in services, url
        assert services[str(url.hostname)].get("image", "").startswith("redis:")
        assert url.port == 6379
        assert service["depends_on"][url.hostname]["condition"] == "service_healthy"
        assert "image" not in service, "built here, never pulled"
        Settings.from_env(quilting_env(service["environment"]))  # valid settings


def test_compose_api_is_the_cpu_image_on_port_8000(services: dict[str, dict[str, Any]]) -> None:
    api = services["api"]
    assert dockerfile_of(api) == DOCKER / "Dockerfile"
    assert "command" not in api  # the image's: quilting serve
    (port,) = api["ports"]
    host, _, container = interpolate(port).rpartition(":")
    assert container == "8000" and host == "8000"
    # The host side is a variable, so that replicas can publish a range (README).
    assert re.fullmatch(r"\$\{QUILTING_API_PORTS:-8000\}:8000", port), port


def test_compose_workers_stop_after_their_drain_grace(services: dict[str, dict[str, Any]]) -> None:
    default = next(d for f, _, d, _ in describe() if f == "drain_grace_s")
    for name in ("worker", "gpu-worker"):
        worker = services[name]
        assert worker["command"] == ["quilting", "worker"]
        build_parser().parse_args(worker["command"][1:])
        assert worker["healthcheck"] == {"disable": True}, "a worker serves no /healthz"
        assert "ports" not in worker
        grace = float(worker["environment"].get("QUILTING_DRAIN_GRACE_S", default))
        assert grace < seconds(worker["stop_grace_period"]) <= grace + 30
    assert dockerfile_of(services["worker"]) == DOCKER / "Dockerfile"
    assert services["worker"]["environment"]["QUILTING_BACKEND"] == "fft"
    assert "profiles" not in services["worker"] and "deploy" not in services["worker"]


def test_compose_gpu_worker_has_one_nvidia_gpu(services: dict[str, dict[str, Any]]) -> None:
    gpu = services["gpu-worker"]
    assert gpu["profiles"] == ["gpu"]
    assert dockerfile_of(gpu) == DOCKER / "Dockerfile.gpu"
    assert gpu["environment"]["QUILTING_BACKEND"] == "gl"
    (device,) = gpu["deploy"]["resources"]["reservations"]["devices"]
    assert device["driver"] == "nvidia"
    assert "gpu" in device["capabilities"]
    # One GPU per worker container: one device id (a count would give every replica GPU 0).
    assert len(device.get("device_ids", [])) == 1 or device.get("count") == 1, device
    for name, service in services.items():
        if name != "gpu-worker":
            assert "deploy" not in service and "profiles" not in service, name
