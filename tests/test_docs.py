"""The documentation stays true: README.md and docs/*.md.

- Every code block runs (page by page, in a temporary folder holding copies of ``examples/`` and
  ``tests/data/``): ``python`` blocks in one namespace per page, ``sh`` blocks with bash and
  this interpreter's ``bin`` (the ``.venv``'s ``quilting``) first on ``PATH``, both against a
  real ``quilting serve`` on a free loopback port that replaces ``http://127.0.0.1:8000``.
  ``json`` blocks must parse; ``text`` blocks may only be generated ones. A block that cannot run
  here has ``<!-- norun: reason -->`` on the line above it.
- The generated regions are what ``docs/generate.py`` writes from the code.
- The README's two commands are CI's test command and docker/install.sh's install lines.
- Links and images resolve; no private jargon reaches the user.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from types import ModuleType
from typing import Any

import httpx
import pytest

from quilting import MatteOptions, SynthesisOptions, TileOptions, TransferOptions

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
#: The service's address in the docs; the tests put their own server's in its place.
DOCS_URL = "http://127.0.0.1:8000"
#: The most blocks that may be left unrun (each with its reason).
MAX_NORUN = 8
LANGUAGES = {"python", "sh", "json", "text"}
BLOCK_TIMEOUT_S = 180

FENCE = re.compile(r"^```(\S*)\s*$")
NORUN = re.compile(r"^<!-- norun: (.+) -->$")
GENERATED_START = re.compile(r"^<!-- generated:(.+) -->$")
GENERATED_END = "<!-- end generated -->"


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    language: str
    code: str
    norun: str | None  # the reason, for a block marked not to run
    generated: bool  # inside a generated region

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def code_blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a Markdown page, in order."""
    lines = page.read_text().splitlines()
    blocks: list[Block] = []
    generated = False
    previous = ""  # the last non-blank line before the current one
    i = 0
    while i < len(lines):
        line = lines[i]
        if GENERATED_START.match(line):
            generated = True
        elif line == GENERATED_END:
            generated = False
        opening = FENCE.match(line)
        if opening and opening[1]:
            end = i + 1
            while end < len(lines) and lines[end] != "```":
                end += 1
            assert end < len(lines), f"{page.name}:{i + 1}: the code block is never closed"
            marker = NORUN.match(previous)
            blocks.append(
                Block(
                    page=page,
                    line=i + 1,
                    language=opening[1],
                    code="\n".join(lines[i + 1 : end]) + "\n",
                    norun=marker[1] if marker else None,
                    generated=generated,
                )
            )
            i = end + 1
            previous = "```"
            continue
        assert not opening, f"{page.name}:{i + 1}: a code block needs a language"
        if line.strip():
            previous = line.strip()
        i += 1
    return blocks


ALL_BLOCKS = [block for page in PAGES for block in code_blocks(page)]


def page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


# --- the service the examples talk to ------------------------------------------------------


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture(scope="session")
def docs_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A real ``quilting serve`` on a free loopback port, for the docs' curl and client blocks."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    log_path = tmp_path_factory.mktemp("docs-server") / "server.log"
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUILTING_")}
    env |= {"QUILTING_WORKERS": "2", "QUILTING_DRAIN_GRACE_S": "5", "PYTHONUNBUFFERED": "1"}
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "quilting", "serve", "--port", str(port)],
            cwd=ROOT,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    try:
        deadline = time.monotonic() + 60
        while True:
            if proc.poll() is not None:
                pytest.fail(f"quilting serve exited:\n{log_path.read_text()}")
            try:
                if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"quilting serve did not answer:\n{log_path.read_text()}")
            time.sleep(0.05)
        yield url
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="session")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Copies of examples/ and tests/data/, made once: the docs' input files."""
    folder = tmp_path_factory.mktemp("docs-inputs")
    shutil.copytree(ROOT / "examples", folder / "examples")
    shutil.copytree(ROOT / "tests" / "data", folder / "tests" / "data")
    return folder


def needs_server(block: Block) -> bool:
    code = block.code
    return DOCS_URL in code or "quilting-remote" in code


def needs_gl(block: Block) -> bool:
    return 'backend="gl"' in block.code or "--backend gl" in block.code


def gl_missing() -> str | None:
    """Why the gl backend cannot run here, or None when it can."""
    from quilting.backends import available_backends

    for status in available_backends():
        if status.name == "gl":
            return None if status.available else status.reason
    return "no gl backend"


def run_python(block: Block, namespace: dict[str, Any], url: str | None) -> None:
    code = block.code if url is None else block.code.replace(DOCS_URL, url)
    try:
        exec(compile(code, block.where, "exec"), namespace)
    except Exception as exc:
        exc.add_note(f"in the python block at {block.where}")
        raise


def run_sh(block: Block, folder: Path, url: str | None) -> None:
    code = block.code if url is None else block.code.replace(DOCS_URL, url)
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUILTING_")}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    if url is not None:
        env["QUILTING_URL"] = url
    done = subprocess.run(
        ["bash", "-e", "-u", "-o", "pipefail", "-c", code],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=BLOCK_TIMEOUT_S,
    )
    if done.returncode != 0:
        pytest.fail(
            f"the sh block at {block.where} exited with {done.returncode}\n--- block\n{code}"
            f"--- stdout\n{done.stdout[-4000:]}\n--- stderr\n{done.stderr[-4000:]}",
            pytrace=False,
        )


#: The pages with blocks to run or check.
PAGES_WITH_CODE = [p for p in PAGES if any(b.page == p and b.norun is None for b in ALL_BLOCKS)]


@pytest.mark.parametrize("page", PAGES_WITH_CODE, ids=page_id)
def test_every_code_block_runs(
    page: Path,
    inputs: Path,
    tmp_path: Path,
    request: pytest.FixtureRequest,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    blocks = [b for b in ALL_BLOCKS if b.page == page and b.norun is None]
    for block in blocks:
        assert block.language in LANGUAGES, f"{block.where}: unknown language {block.language!r}"
    runnable = [b for b in blocks if b.language in ("python", "sh")]
    url = request.getfixturevalue("docs_server") if any(map(needs_server, runnable)) else None
    for name in ("examples", "tests"):
        shutil.copytree(inputs / name, tmp_path / name, copy_function=os.link)
    monkeypatch.chdir(tmp_path)
    for variable in [k for k in os.environ if k.startswith("QUILTING_")]:
        if variable not in ("QUILTING_REQUIRE_GL", "QUILTING_REQUIRE_BROWSER"):
            monkeypatch.delenv(variable)
    if url is not None:
        monkeypatch.setenv("QUILTING_URL", url)
    namespace: dict[str, Any] = {"__name__": "__docs__"}
    for block in blocks:
        if block.language == "json":
            json.loads(block.code)
            continue
        if block.language == "text":
            assert block.generated, f"{block.where}: a text block must be a generated one"
            continue
        if needs_gl(block) and (why := gl_missing()) is not None:
            if os.environ.get("QUILTING_REQUIRE_GL", "").strip() not in ("", "0"):
                pytest.fail(f"{block.where} needs the gl backend, which cannot run: {why}")
            continue  # the GL tests skip the same way on a machine without GL
        if block.language == "python":
            run_python(block, namespace, url if needs_server(block) else None)
        else:
            run_sh(block, tmp_path, url if needs_server(block) else None)


def test_blocks_are_found() -> None:
    # The runner above is only as good as the extraction: it sees every kind of block.
    languages = {b.language for b in ALL_BLOCKS}
    assert {"python", "sh", "json", "text"} <= languages
    assert sum(b.language == "python" for b in ALL_BLOCKS) >= 15
    assert sum(b.language == "sh" for b in ALL_BLOCKS) >= 15
    assert any(needs_server(b) and b.language == "sh" for b in ALL_BLOCKS)
    assert any(needs_server(b) and b.language == "python" for b in ALL_BLOCKS)


def test_few_blocks_are_left_unrun_and_each_says_why() -> None:
    unrun = [b for b in ALL_BLOCKS if b.norun is not None]
    listing = "\n".join(f"{b.where}: {b.norun}" for b in unrun)
    assert len(unrun) <= MAX_NORUN, listing
    for block in unrun:
        assert block.norun is not None and len(block.norun.split()) >= 3, block.where
        assert block.language == "sh", block.where


def test_the_problem_example_is_what_the_service_answers(docs_server: str) -> None:
    # The one JSON block that is a problem document (others show files, a Wang manifest).
    (example,) = [b for b in ALL_BLOCKS if b.language == "json" and '"status"' in b.code]
    response = httpx.post(
        docs_server + "/synthesize",
        files={"texture": ("brick.png", (ROOT / "examples" / "brick.png").read_bytes())},
        data={"options": json.dumps({"width": 256, "height": 256, "overlap": 30})},
        timeout=30,
    )
    assert response.status_code == 422
    assert response.headers["content-type"].startswith("application/problem+json")
    assert json.loads(example.code) == response.json()


# --- the README's two commands --------------------------------------------------------------


def readme_commands() -> list[str]:
    section = README.read_text().split("\n## Two commands\n")[1].split("\n## ")[0]
    return [b.code.strip() for b in ALL_BLOCKS if b.page == README and b.code in section]


def test_the_readme_test_command_is_what_ci_runs() -> None:
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert readme_commands()[1] == ci


def test_the_readme_install_is_the_install_script_s() -> None:
    script = [line.strip() for line in (ROOT / "docker" / "install.sh").read_text().splitlines()]
    venv, pip, serve = readme_commands()[0].split(" && ")
    assert venv in script
    # The development install of the ci role, with the service's extra instead of dev's.
    assert pip.replace("'.[server]'", "'.[dev]'") in script, pip
    assert serve == ".venv/bin/quilting serve"
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert "\nserver = [" in pyproject


def test_the_readme_is_a_front_door() -> None:
    text = README.read_text()
    assert len(text.splitlines()) <= 150
    for page in PAGES[1:]:
        if page.name != "README.md":
            assert f"](docs/{page.name})" in text, f"the README does not link {page.name}"


# --- generated regions --------------------------------------------------------------------


def generator() -> ModuleType:
    spec = importlib.util.spec_from_file_location("docs_generate", ROOT / "docs" / "generate.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_generated_regions_are_what_the_code_gives() -> None:
    generate = generator()
    stale = [
        p.name
        for p in generate.markdown_files()
        if generate.rewrite(p.read_text()) != p.read_text()
    ]
    assert not stale, f"run .venv/bin/python docs/generate.py; stale: {stale}"


def test_the_generator_check_fails_on_drift(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    generate = generator()
    page = tmp_path / "page.md"
    page.write_text("text\n<!-- generated:options TileOptions -->\nold\n<!-- end generated -->\n")
    monkeypatch.setattr(generate, "markdown_files", lambda: [page])
    monkeypatch.setattr(generate, "ROOT", tmp_path)
    assert generate.main(["--check"]) == 1
    assert "old" in page.read_text()  # --check changes nothing
    assert generate.main([]) == 0
    assert "| `band` |" in page.read_text() and "old" not in page.read_text()
    assert generate.main(["--check"]) == 0


def regions(page: Path) -> dict[str, str]:
    text = page.read_text()
    found = re.findall(r"<!-- generated:([^>]*?) -->\n(.*?)<!-- end generated -->", text, re.S)
    return {spec.strip(): body for spec, body in found}


def test_every_option_is_in_a_generated_table() -> None:
    tables = regions(ROOT / "docs" / "parameters.md")
    synthesis = tables["options SynthesisOptions"]
    for f in fields(SynthesisOptions):
        assert f"| `{f.name}` |" in synthesis, f.name
    for cls in (TransferOptions, MatteOptions):
        own = tables[f"options {cls.__name__} beyond SynthesisOptions"]
        for f in fields(cls):
            assert f"| `{f.name}` |" in own or f"| `{f.name}` |" in synthesis, (cls, f.name)
    for f in fields(TileOptions):
        assert f"| `{f.name}` |" in tables["options TileOptions"], f.name


def test_every_setting_is_in_the_generated_table() -> None:
    from quilting.service.settings import describe

    table = regions(ROOT / "docs" / "http-service.md")["settings"]
    for _, variable, _, _ in describe():
        assert f"| `{variable}` |" in table, variable


def test_the_signatures_are_generated() -> None:
    specs = {spec for page in PAGES for spec in regions(page)}
    for name in ("quilting.synthesize", "quilting.transfer", "quilting.matte"):
        assert f"signature {name}" in specs, name
    assert "usage" in specs


# --- links, words, addresses -----------------------------------------------------------------


def prose(page: Path) -> str:
    """The page without its code blocks."""
    return re.sub(r"^```\S*\n.*?^```$", "", page.read_text(), flags=re.S | re.M)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower().replace("`", ""))
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    return {slug(m) for m in re.findall(r"^#+ (.+)$", prose(page), flags=re.M)}


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_links_and_images_resolve(page: Path) -> None:
    for target in re.findall(r"\]\(([^)\s]+)\)", prose(page)):
        if re.match(r"[a-z]+://", target) or target.startswith("mailto:"):
            continue
        path, _, anchor = target.partition("#")
        linked = (page.parent / path).resolve() if path else page
        assert linked.exists(), f"{page_id(page)}: {target} does not exist"
        assert ROOT in linked.parents or linked == ROOT, (
            f"{page_id(page)}: {target} leaves the repo"
        )
        if anchor:
            assert linked.suffix == ".md", target
            assert anchor in anchors(linked), f"{page_id(page)}: no heading #{anchor} in {path}"


JARGON = re.compile(r"seed 00[0-9]|DESIGN §|DESIGN\.md|shared/seeds|seeds/", re.I)


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_no_private_jargon(page: Path) -> None:
    for number, line in enumerate(page.read_text().splitlines(), 1):
        assert not JARGON.search(line), f"{page_id(page)}:{number}: {line}"


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_one_service_address(page: Path) -> None:
    # The runner replaces DOCS_URL; any other local address would reach no server.
    text = page.read_text()
    assert "localhost" not in text
    allowed = {DOCS_URL.removeprefix("http://"), "127.0.0.1:6379"}  # the service's, Redis's
    for address in re.findall(r"127\.0\.0\.1:\d+", text):
        assert address in allowed, f"{page_id(page)}: {address}"


def test_every_module_says_its_role() -> None:
    # docs/architecture.md's code map is each module's docstring: none may be missing.
    import ast

    for folder in ("server/quilting", "client/quilting_client"):
        for path in (ROOT / folder).rglob("*.py"):
            doc = ast.get_docstring(ast.parse(path.read_text()))
            assert doc and doc.strip(), f"{path.relative_to(ROOT)} has no module docstring"
