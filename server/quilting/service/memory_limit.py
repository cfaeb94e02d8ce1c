"""Memory limits of the service's child processes, and byte counts in words.

A sandbox process (:mod:`quilting.service.sandbox`) and a job worker process
(:mod:`quilting.service.jobs.worker`) each cap their own memory once they have imported what
they need (:func:`limit_memory`), so that an upload or a job past its budget ends in a
``MemoryError`` there, never in the API process; their problems name the budget with
:func:`describe_bytes`.
"""

from __future__ import annotations

import logging
import resource

log = logging.getLogger("quilting.service")

MiB = 1 << 20
GiB = 1 << 30


def _status_bytes(field: str) -> int | None:
    """A ``kB`` line of ``/proc/self/status`` (VmData, VmSize...) in bytes; None off Linux."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def limit_memory(budget: int) -> int | None:
    """Cap this process's memory at what it uses now plus ``budget`` bytes; returns the cap.

    The cap is RLIMIT_DATA over the current VmData (private writable memory: the heap and
    every anonymous mapping, numpy's arrays among them), not RLIMIT_AS over VmSize. Measured
    on the engine (2 cores, fft backend): RLIMIT_AS also counts address space that is reserved
    and never used - glibc reserves 64 MiB per malloc arena of each thread the FFT pool
    starts, so VmSize grew 180 MiB on the first job with RSS unchanged - and at a small budget
    a 4096x4096 synthesis took 92 s to reach its MemoryError under RLIMIT_AS (arenas refused,
    threads contending for one) against 6 s under RLIMIT_DATA. Both raise MemoryError in numpy
    when the budget is spent, and the process goes on afterwards. (Not measured here: how a GPU
    driver's mappings count; shared mappings of device memory do not count under RLIMIT_DATA.)

    Parameters
    ----------
    budget : int
        Bytes this process may allocate beyond what it holds now.

    Returns
    -------
    int or None
        The cap set, in bytes; None (and nothing limited) where ``/proc/self/status`` cannot
        be read.
    """
    used = _status_bytes("VmData")
    if used is None:
        log.warning("cannot read /proc/self/status: memory of this process is not limited")
        return None
    _, hard = resource.getrlimit(resource.RLIMIT_DATA)
    cap = used + budget
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_DATA, (cap, hard))
    return cap


def describe_bytes(count: int) -> str:
    """A byte count for people: ``2 GiB``, ``150 MiB``."""
    if count >= GiB:
        return f"{count / GiB:.3g} GiB"
    # Three figures, never an exponent: 1000 to 1023 MiB read as such, not "1e+03 MiB".
    mib = count / MiB
    if mib >= 100:
        return f"{mib:.0f} MiB"
    return f"{mib:.3g} MiB" if mib >= 0.01 or mib == 0 else f"{mib:.2f} MiB"
