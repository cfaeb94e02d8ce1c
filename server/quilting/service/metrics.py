"""The Prometheus exposition of the service's figures (``GET /metrics``): jobs by status,
finished jobs, queue depth, running jobs, the job-time histogram, pixels made, bytes kept."""

from __future__ import annotations

from quilting.service.jobs import HISTOGRAM_BUCKETS, Figures


def metrics_text(figures: Figures) -> str:
    lines = [
        "# HELP quilting_jobs Jobs known to the service, by status.",
        "# TYPE quilting_jobs gauge",
    ]
    lines += [f'quilting_jobs{{status="{s}"}} {n}' for s, n in figures.counts.items()]
    lines += [
        "# HELP quilting_jobs_finished_total Jobs finished, by final status.",
        "# TYPE quilting_jobs_finished_total counter",
    ]
    lines += [
        f'quilting_jobs_finished_total{{status="{s}"}} {n}'
        for s, n in figures.finished_total.items()
    ]
    lines += [
        "# HELP quilting_queue_depth Jobs waiting for a worker.",
        "# TYPE quilting_queue_depth gauge",
        f"quilting_queue_depth {figures.queued}",
        "# HELP quilting_jobs_running Jobs being computed.",
        "# TYPE quilting_jobs_running gauge",
        f"quilting_jobs_running {figures.running}",
        "# HELP quilting_job_seconds Time from start to end of a job.",
        "# TYPE quilting_job_seconds histogram",
    ]
    cumulative = 0
    for bound, count in zip(HISTOGRAM_BUCKETS, figures.seconds_buckets, strict=False):
        cumulative += count
        lines.append(f'quilting_job_seconds_bucket{{le="{bound}"}} {cumulative}')
    total = sum(figures.seconds_buckets)
    lines += [
        f'quilting_job_seconds_bucket{{le="+Inf"}} {total}',
        f"quilting_job_seconds_sum {figures.seconds_sum}",
        f"quilting_job_seconds_count {total}",
        "# HELP quilting_pixels_produced_total Output pixels of finished jobs.",
        "# TYPE quilting_pixels_produced_total counter",
        f"quilting_pixels_produced_total {figures.pixels_total}",
        "# HELP quilting_results_bytes Bytes of results kept.",
        "# TYPE quilting_results_bytes gauge",
        f"quilting_results_bytes {figures.kept_bytes}",
    ]
    return "\n".join(lines) + "\n"
