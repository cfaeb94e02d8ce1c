"""The codebase's shape, as issue 22 measures it: repetition, module sizes, layers, the suite.

Prints one table per figure, for this checkout and, with ``--against REV``, for another commit
checked out in a temporary git worktree (the same run, the same tools):

- ``duplicates``: the pairs of places sharing six or more lines that the ``duplicates`` tool
  finds (skipped when it is not on PATH), all of them and those between the sync and the async
  client;
- the largest modules of ``server/quilting/service`` and the lines of ``create_app``;
- imports of ``quilting.core`` / ``quilting.costs`` from the service and the CLI (the layer
  rule: none);
- with ``--suite``, the wall time of the whole test suite (minutes; slow, and only comparable
  within one run on a quiet machine).

Run: ``.venv/bin/python benchmarks/bench_codebase.py --against fff654a``.
"""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchtools import machine, parser, show_machine, table, write_json

ROOT = Path(__file__).resolve().parent.parent
SERVICE = Path("server/quilting/service")
LAYER = re.compile(r"^\s*(from|import)\s+quilting\.(core|costs)\b", re.M)


def duplicates(tree: Path) -> dict[str, int] | None:
    """Pairs the ``duplicates`` tool lists in ``tree``: all, and sync~async client ones."""
    tool = shutil.which("duplicates")
    if tool is None:
        return None
    out = subprocess.run(
        [tool, "--most", "200", "--seconds", "300"],
        cwd=tree,
        capture_output=True,
        text=True,
        check=False,
    ).stdout
    rows = [line for line in out.splitlines() if re.match(r"D\d+ ", line)]
    between = [r for r in rows if "_async.py" in r and "_sync.py" in r]
    runs = sum(1 + int(m.group(1)) for r in between if (m := re.search(r"\+(\d+) more", r)))
    runs += sum(1 for r in between if "more run" not in r)
    return {
        "pairs": len(rows),
        "boilerplate": sum("boilerplate" in r for r in rows),
        "sync_async_runs": runs,
    }


def service_sizes(tree: Path) -> dict[str, int]:
    """Lines of each module of the service (the three largest are shown)."""
    return {
        str(path.relative_to(tree / SERVICE)): len(path.read_text().splitlines())
        for path in sorted((tree / SERVICE).rglob("*.py"))
    }


def create_app_lines(tree: Path) -> int:
    """Lines of ``create_app``, decorators and docstring included."""
    module = ast.parse((tree / SERVICE / "app.py").read_text())
    for node in module.body:
        if isinstance(node, ast.FunctionDef) and node.name == "create_app":
            assert node.end_lineno is not None
            return node.end_lineno - node.lineno + 1
    raise LookupError("no create_app in service/app.py")


def layer_breaches(tree: Path) -> int:
    """Imports of the engine's internals from the service or the CLI."""
    files = [*(tree / SERVICE).rglob("*.py"), tree / "server/quilting/cli.py"]
    return sum(len(LAYER.findall(path.read_text())) for path in files)


def suite_minutes(tree: Path) -> float:
    """Wall time of the whole test suite in ``tree``, with this interpreter."""
    started = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-x"],
        cwd=tree,
        check=False,
        capture_output=True,
    )
    return (time.perf_counter() - started) / 60


def measure(tree: Path, suite: bool) -> dict[str, object]:
    sizes = service_sizes(tree)
    largest = sorted(sizes.items(), key=lambda item: -item[1])[:3]
    return {
        "duplicates": duplicates(tree),
        "largest_service_modules": largest,
        "create_app_lines": create_app_lines(tree),
        "layer_breaches": layer_breaches(tree),
        "suite_minutes": suite_minutes(tree) if suite else None,
    }


def main() -> int:
    args = parser(__doc__)
    args.add_argument("--against", help="also measure this commit (a temporary worktree)")
    args.add_argument("--suite", action="store_true", help="time the whole test suite too")
    options = args.parse_args()
    show_machine(machine())
    trees = {"this checkout": ROOT}
    with tempfile.TemporaryDirectory() as scratch:
        if options.against:
            other = Path(scratch) / "against"
            subprocess.run(
                ["git", "worktree", "add", "-q", "--detach", str(other), options.against],
                cwd=ROOT,
                check=True,
            )
            trees = {options.against: other, **trees}
        try:
            results = {name: measure(tree, options.suite) for name, tree in trees.items()}
        finally:
            if options.against:
                subprocess.run(
                    ["git", "worktree", "remove", "--force", str(other)], cwd=ROOT, check=False
                )
    rows = []
    for name, found in results.items():
        dups = found["duplicates"]
        assert dups is None or isinstance(dups, dict)
        largest = found["largest_service_modules"]
        assert isinstance(largest, list)
        rows.append(
            [
                name,
                "-" if dups is None else str(dups["pairs"]),
                "-" if dups is None else str(dups["boilerplate"]),
                "-" if dups is None else str(dups["sync_async_runs"]),
                f"{largest[0][0]} {largest[0][1]}",
                str(found["create_app_lines"]),
                str(found["layer_breaches"]),
                "-" if found["suite_minutes"] is None else f"{found['suite_minutes']:.1f}",
            ]
        )
    print(
        table(
            [
                "tree",
                "dup pairs",
                "boilerplate",
                "sync~async runs",
                "largest service module",
                "create_app lines",
                "core/costs imports",
                "suite min",
            ],
            rows,
        )
    )
    write_json(options.json, results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
