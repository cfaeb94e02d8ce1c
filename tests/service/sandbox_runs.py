"""Running a body of async calls against a started :class:`~quilting.service.sandbox.Sandbox`
and closing it after, for the sandbox's tests (``test_sandbox.py``, ``test_sandbox_process.py``)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import TypeVar

from quilting.service.sandbox import Sandbox

T = TypeVar("T")


def run_sandbox(sandbox: Sandbox, body: Callable[[Sandbox], Awaitable[T]]) -> T:
    """``body(sandbox)`` on a fresh event loop, the sandbox started before and closed after."""

    async def main() -> T:
        await sandbox.start()
        try:
            return await body(sandbox)
        finally:
            await sandbox.close()

    return asyncio.run(main())
