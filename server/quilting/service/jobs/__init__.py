"""The job store: what a job is (:mod:`.model`), the queue the app talks to (:mod:`.queue`),
jobs kept in this process (:mod:`.memory`) or in Redis (:mod:`.redis_store`, with its Lua
script ``jobs.lua``) and sent to ``quilting worker`` processes through Dramatiq
(:mod:`.dramatiq_queue`), and the workers that compute them (:mod:`.worker`).

The job's model is re-exported here; the stores are imported from their modules (Redis and
Dramatiq only where they are used).
"""

from quilting.service.jobs.model import (
    HISTOGRAM_BUCKETS,
    MATTE_OUTPUTS,
    Figures,
    Job,
    JobInput,
    PixelLimits,
    Status,
    new_job_id,
)

__all__ = [
    "HISTOGRAM_BUCKETS",
    "MATTE_OUTPUTS",
    "Figures",
    "Job",
    "JobInput",
    "PixelLimits",
    "Status",
    "new_job_id",
]
