"""Unit tests of :func:`quilting.service.metrics.metrics_text`, the ``/metrics`` exposition.

Covers the Prometheus text for hand-made :class:`~quilting.service.jobs.Figures`: every line
of one exposition, exactly; each family's HELP and TYPE once, before its samples; the
labelled gauges and counters in the figures' order (none when a mapping is empty); the
job-time histogram (a ``le`` bucket per :data:`HISTOGRAM_BUCKETS` bound, counts cumulative,
the jobs past the last bound only in ``+Inf``, which equals ``_count``); and the text of an
empty store's figures.
"""

from __future__ import annotations

import re
from dataclasses import replace

import pytest

from quilting.service.jobs import HISTOGRAM_BUCKETS, Figures
from quilting.service.jobs.model import Status
from quilting.service.metrics import metrics_text

#: One sample line: a name, labels maybe, and a number.
SAMPLE = re.compile(r'^([a-z_]+)(?:\{([a-z]+)="([^"\\]*)"\})? (\S+)$')


def figures(**changes: object) -> Figures:
    """Figures of a store that has seen a few jobs (13 buckets: 12 bounds and past them)."""
    base = Figures(
        counts={"queued": 2, "running": 1, "done": 5, "failed": 0, "cancelled": 1},
        finished_total={"done": 7, "failed": 2, "cancelled": 1},
        seconds_buckets=[1, 0, 2, 0, 3, 0, 0, 1, 0, 0, 0, 0, 2],
        seconds_sum=741.25,
        pixels_total=123_456_789,
        kept_bytes=9_876_543,
        queued=2,
        running=1,
    )
    return replace(base, **changes)  # type: ignore[arg-type]


def samples(text: str) -> dict[str, float]:
    """Each sample of ``text`` by ``name{label="value"}`` (or ``name``)."""
    found: dict[str, float] = {}
    for line in text.splitlines():
        if line.startswith("#"):
            continue
        match = SAMPLE.match(line)
        assert match, line
        name, label, value, number = match.groups()
        key = f'{name}{{{label}="{value}"}}' if label else name
        assert key not in found, key
        found[key] = float(number)
    return found


def test_the_whole_exposition_line_by_line() -> None:
    expected = """\
# HELP quilting_jobs Jobs known to the service, by status.
# TYPE quilting_jobs gauge
quilting_jobs{status="queued"} 2
quilting_jobs{status="running"} 1
quilting_jobs{status="done"} 5
quilting_jobs{status="failed"} 0
quilting_jobs{status="cancelled"} 1
# HELP quilting_jobs_finished_total Jobs finished, by final status.
# TYPE quilting_jobs_finished_total counter
quilting_jobs_finished_total{status="done"} 7
quilting_jobs_finished_total{status="failed"} 2
quilting_jobs_finished_total{status="cancelled"} 1
# HELP quilting_queue_depth Jobs waiting for a worker.
# TYPE quilting_queue_depth gauge
quilting_queue_depth 2
# HELP quilting_jobs_running Jobs being computed.
# TYPE quilting_jobs_running gauge
quilting_jobs_running 1
# HELP quilting_job_seconds Time from start to end of a job.
# TYPE quilting_job_seconds histogram
quilting_job_seconds_bucket{le="0.05"} 1
quilting_job_seconds_bucket{le="0.1"} 1
quilting_job_seconds_bucket{le="0.25"} 3
quilting_job_seconds_bucket{le="0.5"} 3
quilting_job_seconds_bucket{le="1.0"} 6
quilting_job_seconds_bucket{le="2.5"} 6
quilting_job_seconds_bucket{le="5.0"} 6
quilting_job_seconds_bucket{le="10.0"} 7
quilting_job_seconds_bucket{le="30.0"} 7
quilting_job_seconds_bucket{le="60.0"} 7
quilting_job_seconds_bucket{le="120.0"} 7
quilting_job_seconds_bucket{le="300.0"} 7
quilting_job_seconds_bucket{le="+Inf"} 9
quilting_job_seconds_sum 741.25
quilting_job_seconds_count 9
# HELP quilting_pixels_produced_total Output pixels of finished jobs.
# TYPE quilting_pixels_produced_total counter
quilting_pixels_produced_total 123456789
# HELP quilting_results_bytes Bytes of results kept.
# TYPE quilting_results_bytes gauge
quilting_results_bytes 9876543
"""
    assert HISTOGRAM_BUCKETS == (
        0.05,
        0.1,
        0.25,
        0.5,
        1.0,
        2.5,
        5.0,
        10.0,
        30.0,
        60.0,
        120.0,
        300.0,
    )
    assert metrics_text(figures()) == expected


def test_each_family_has_one_help_and_one_type_before_its_samples() -> None:
    families = {
        "quilting_jobs": "gauge",
        "quilting_jobs_finished_total": "counter",
        "quilting_queue_depth": "gauge",
        "quilting_jobs_running": "gauge",
        "quilting_job_seconds": "histogram",
        "quilting_pixels_produced_total": "counter",
        "quilting_results_bytes": "gauge",
    }
    text = metrics_text(figures())
    assert text.endswith("\n") and "\n\n" not in text
    current: str | None = None
    helped: list[str] = []
    typed: dict[str, str] = {}
    for line in text.splitlines():
        if line.startswith("# HELP "):
            name = line.split()[2]
            assert line.split(maxsplit=3)[3].strip(), line  # some help text
            helped.append(name)
        elif line.startswith("# TYPE "):
            _, _, name, kind = line.split()
            assert name not in typed and helped[-1] == name, line
            typed[name] = kind
            current = name
        else:
            assert current is not None, line
            sample = SAMPLE.match(line)
            assert sample, line
            name = sample.group(1)
            suffixes = ("_bucket", "_sum", "_count") if typed[current] == "histogram" else ("",)
            assert name in {current + s for s in suffixes}, (current, line)
    assert helped == list(families)
    assert typed == families


def test_the_histogram_is_cumulative_and_inf_counts_every_job() -> None:
    buckets = [3, 1, 4, 1, 5, 9, 2, 6, 5, 3, 5, 8, 7]  # the last: jobs past 300 s
    text = metrics_text(figures(seconds_buckets=buckets, seconds_sum=0.5))
    found = samples(text)
    bounds = [f'quilting_job_seconds_bucket{{le="{b}"}}' for b in HISTOGRAM_BUCKETS]
    cumulative = [found[bound] for bound in bounds]
    assert cumulative == [float(sum(buckets[: i + 1])) for i in range(len(HISTOGRAM_BUCKETS))]
    assert cumulative == sorted(cumulative)
    total = float(sum(buckets))
    assert found['quilting_job_seconds_bucket{le="+Inf"}'] == total
    assert found["quilting_job_seconds_count"] == total
    assert found['quilting_job_seconds_bucket{le="+Inf"}'] - cumulative[-1] == buckets[-1]
    assert found["quilting_job_seconds_sum"] == 0.5
    # One bucket per bound, in order, then +Inf.
    les = re.findall(r'^quilting_job_seconds_bucket\{le="([^"]+)"\}', text, re.MULTILINE)
    assert les[-1] == "+Inf"
    assert [float(le) for le in les[:-1]] == list(HISTOGRAM_BUCKETS)


def test_no_jobs_yet() -> None:
    empty = Figures(
        counts={s.value: 0 for s in Status},
        finished_total={},
        seconds_buckets=[0] * (len(HISTOGRAM_BUCKETS) + 1),
        seconds_sum=0.0,
        pixels_total=0,
        kept_bytes=0,
        queued=0,
        running=0,
    )
    found = samples(metrics_text(empty))
    assert {k: v for k, v in found.items() if k.startswith("quilting_jobs{")} == {
        f'quilting_jobs{{status="{s.value}"}}': 0.0 for s in Status
    }
    assert not any(k.startswith("quilting_jobs_finished_total") for k in found)
    assert "# TYPE quilting_jobs_finished_total counter" in metrics_text(empty)
    assert set(found.values()) == {0.0}
    assert found['quilting_job_seconds_bucket{le="+Inf"}'] == 0
    assert len([k for k in found if k.startswith("quilting_job_seconds_bucket")]) == (
        len(HISTOGRAM_BUCKETS) + 1
    )


@pytest.mark.parametrize(
    ("changes", "line"),
    [
        ({"queued": 17}, "quilting_queue_depth 17"),
        ({"running": 3}, "quilting_jobs_running 3"),
        ({"pixels_total": 4096 * 4096}, "quilting_pixels_produced_total 16777216"),
        ({"kept_bytes": 0}, "quilting_results_bytes 0"),
        ({"seconds_sum": 0.1 + 0.2}, f"quilting_job_seconds_sum {0.1 + 0.2!r}"),
        ({"counts": {"running": 4}}, 'quilting_jobs{status="running"} 4'),
        ({"finished_total": {"failed": 11}}, 'quilting_jobs_finished_total{status="failed"} 11'),
    ],
    ids=["queued", "running", "pixels", "kept", "sum", "counts", "finished"],
)
def test_each_figure_has_its_line(changes: dict[str, object], line: str) -> None:
    text = metrics_text(figures(**changes))
    assert line in text.splitlines()
    assert samples(text)  # and the rest still parses
