"""The job store: what a job is (:mod:`.model`) and what it was given (:mod:`.job_input`; the
files it shares with a submission, :mod:`.job_files`), the queue the app talks to
(:mod:`.queue`), jobs kept in this process (:mod:`.memory`) or in Redis (:mod:`.redis_store`,
with its Lua script ``jobs.lua``) and sent to ``quilting worker`` processes through Dramatiq
(:mod:`.dramatiq_queue`), and the workers that compute them (:mod:`.worker`, each
operation's result: :mod:`.results`).

The job's model and input are re-exported here; the stores are imported from their modules
(Redis and Dramatiq only where they are used).
"""

from quilting.service.jobs.job_input import MATTE_OUTPUTS, JobInput, PixelLimits
from quilting.service.jobs.model import (
    HISTOGRAM_BUCKETS,
    Figures,
    Job,
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
