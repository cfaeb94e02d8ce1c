-- Job state in Redis: every change of a job's state is one call of this script, so it is
-- atomic whatever number of API replicas and workers share the server.
--
-- KEYS[1] is the key prefix; ARGV[1] the command; the rest are the command's arguments.
-- Keys (P = prefix):
--   P:job:ID     hash   the job record (status, progress, stage, times, figures, flags)
--   P:input:ID   string the job's input (JobInput.to_bytes), deleted once the job is final
--   P:out:ID     hash   the results: "png", "layout", "c:NAME" (companions)
--   P:queued     set    ids of queued jobs (the queue_full cap)
--   P:running    set    ids of running jobs
--   P:kept       zset   ids of jobs whose results are kept, by finish time (caps, expiry)
--   P:kept_size  hash   id -> bytes of its results
--   P:records    zset   ids of final jobs, by finish time (records are forgotten past a cap)
--   P:stats      hash   counters of /metrics
--   P:workers    zset   worker id -> time of its last heartbeat
--   P:idem:O:K   string [digest, id] of an Idempotency-Key K of owner O
-- luacheck: globals ARGV KEYS redis cjson unpack

local prefix = KEYS[1]
local command = ARGV[1]
local queued = prefix .. ":queued"
local running = prefix .. ":running"
local kept = prefix .. ":kept"
local kept_size = prefix .. ":kept_size"
local records = prefix .. ":records"
local stats = prefix .. ":stats"
local workers = prefix .. ":workers"
-- Upper bounds of the job duration histogram (HISTOGRAM_BUCKETS), put here when loaded.
local BUCKETS = {__BUCKETS__}

local function job_key(id) return prefix .. ":job:" .. id end
local function input_key(id) return prefix .. ":input:" .. id end
local function out_key(id) return prefix .. ":out:" .. id end

local function is_final(status)
    return status == "done" or status == "failed" or status == "cancelled"
end

-- The job's Idempotency-Key may be used again, for a new job.
local function forget_idem(id, idem)
    if idem and idem ~= "" then
        local seen = redis.call("get", idem)
        if seen and cjson.decode(seen)[2] == id then
            redis.call("del", idem)
        end
    end
end

-- The results of a job are no longer kept: its record says so (410 result_expired), and its
-- Idempotency-Key is free again (as in the in-memory store).
local function drop_results(id)
    forget_idem(id, redis.call("hget", job_key(id), "idem"))
    local size = redis.call("hget", kept_size, id)
    if size then
        redis.call("hincrby", stats, "kept_bytes", -tonumber(size))
        redis.call("hdel", kept_size, id)
    end
    redis.call("zrem", kept, id)
    redis.call("del", out_key(id))
    if redis.call("exists", job_key(id)) == 1 then
        redis.call("hset", job_key(id), "expired", "1")
    end
end

-- Records of final jobs beyond `limit` are forgotten, oldest first (404 afterwards).
local function forget_old(limit)
    while redis.call("zcard", records) > limit do
        local id = redis.call("zpopmin", records)[1]
        local job = job_key(id)
        local status, idem = unpack(redis.call("hmget", job, "status", "idem"))
        if status then
            redis.call("hincrby", stats, "known:" .. status, -1)
        end
        forget_idem(id, idem)
        drop_results(id)
        redis.call("del", job, input_key(id))
    end
end

-- A job reaches its final status: counters, duration histogram, record cap.
local function finalize(id, status, now, limit)
    local job = job_key(id)
    local old, started = unpack(redis.call("hmget", job, "status", "started"))
    redis.call("srem", queued, id)
    redis.call("srem", running, id)
    redis.call("hincrby", stats, "known:" .. old, -1)
    redis.call("hincrby", stats, "known:" .. status, 1)
    redis.call("hset", job, "status", status, "stage", status, "finished", now)
    if status == "done" then
        redis.call("hset", job, "progress", "1")
    end
    redis.call("del", input_key(id))
    redis.call("hincrby", stats, "total:" .. status, 1)
    if started and started ~= "" then
        local seconds = tonumber(now) - tonumber(started)
        redis.call("hincrbyfloat", stats, "seconds_sum", seconds)
        local bucket = #BUCKETS
        for i, bound in ipairs(BUCKETS) do
            if seconds <= bound then
                bucket = i - 1
                break
            end
        end
        redis.call("hincrby", stats, "bucket:" .. bucket, 1)
    end
    redis.call("zadd", records, now, id)
    forget_old(limit)
end

if command == "add" then
    -- add ID NOW MAX_QUEUED IDEM_KEY DIGEST INPUT FIELD VALUE ...
    local id, max_queued, idem, digest, input = ARGV[2], tonumber(ARGV[4]), ARGV[5], ARGV[6], ARGV[7]
    if idem ~= "" then
        local seen = redis.call("get", idem)
        if seen then
            local earlier = cjson.decode(seen)
            if redis.call("exists", job_key(earlier[2])) == 1 then
                if earlier[1] ~= digest then
                    return {"conflict"}
                end
                return {"existing", earlier[2]}
            end
        end
    end
    local depth = redis.call("scard", queued)
    if depth >= max_queued then
        return {"full", depth}
    end
    local fields = {}
    for i = 8, #ARGV do
        fields[#fields + 1] = ARGV[i]
    end
    redis.call("hset", job_key(id), "status", "queued", "idem", idem, unpack(fields))
    redis.call("set", input_key(id), input)
    redis.call("sadd", queued, id)
    redis.call("hincrby", stats, "known:queued", 1)
    if idem ~= "" then
        redis.call("set", idem, cjson.encode({digest, id}))
    end
    return {"created"}

elseif command == "drop" then
    -- drop ID: a job whose message could not be queued is taken back (never seen by anyone).
    local id = ARGV[2]
    local job = job_key(id)
    if redis.call("hget", job, "status") == "queued" then
        local idem = redis.call("hget", job, "idem")
        if idem and idem ~= "" then
            redis.call("del", idem)
        end
        redis.call("srem", queued, id)
        redis.call("hincrby", stats, "known:queued", -1)
        redis.call("del", job, input_key(id))
    end
    return "ok"

elseif command == "claim" then
    -- claim ID NOW WORKER MAX_ATTEMPTS LIMIT ABANDONED_ERROR STALE_BEFORE
    local id, now, worker, max_attempts, limit = ARGV[2], ARGV[3], ARGV[4], tonumber(ARGV[5]), tonumber(ARGV[6])
    local job = job_key(id)
    local status, cancel, owner = unpack(redis.call("hmget", job, "status", "cancel", "worker"))
    if not status then
        return {"gone"}
    end
    if is_final(status) then
        return {"final"}
    end
    if status == "running" and owner ~= worker then
        -- A second delivery: the job is taken over only from a worker that stopped beating.
        local beat = redis.call("zscore", workers, owner)
        if beat and tonumber(beat) > tonumber(ARGV[8]) then
            return {"busy"}
        end
    end
    if cancel == "1" then
        finalize(id, "cancelled", now, limit)
        return {"cancelled"}
    end
    -- Every delivery counts, so a job that kills its workers cannot loop for ever.
    local attempt = redis.call("hincrby", job, "attempt", 1)
    if attempt > max_attempts then
        redis.call("hset", job, "error", ARGV[7])
        finalize(id, "failed", now, limit)
        return {"abandoned"}
    end
    if status == "queued" then
        redis.call("srem", queued, id)
        redis.call("sadd", running, id)
        redis.call("hincrby", stats, "known:queued", -1)
        redis.call("hincrby", stats, "known:running", 1)
    end
    redis.call("hset", job, "status", "running", "stage", "decoding", "progress", "0",
        "started", now, "worker", worker)
    return {"run", attempt, redis.call("get", input_key(id))}

elseif command == "progress" then
    -- progress ID ATTEMPT FRACTION STAGE -> ok | cancel | stale (another attempt owns the job)
    local job = job_key(ARGV[2])
    local status, attempt, cancel = unpack(redis.call("hmget", job, "status", "attempt", "cancel"))
    if status ~= "running" or attempt ~= ARGV[3] then
        return "stale"
    end
    redis.call("hset", job, "progress", ARGV[4], "stage", ARGV[5])
    if cancel == "1" then
        return "cancel"
    end
    return "ok"

elseif command == "finish" then
    -- finish ID NOW STATUS LIMIT MAX_COUNT MAX_BYTES TTL_MS PIXELS NFIELDS FIELD VALUE ...
    --        NAME BYTES ... (outputs of a done job)
    local id, now, status, limit = ARGV[2], ARGV[3], ARGV[4], tonumber(ARGV[5])
    local max_count, max_bytes, ttl_ms = tonumber(ARGV[6]), tonumber(ARGV[7]), tonumber(ARGV[8])
    local pixels, nfields = tonumber(ARGV[9]), tonumber(ARGV[10])
    local job = job_key(id)
    local current, cancel = unpack(redis.call("hmget", job, "status", "cancel"))
    -- The first attempt to finish wins; a later one (a job run twice) changes nothing.
    if current ~= "running" then
        return "duplicate"
    end
    if status == "cancelled" and cancel ~= "1" then
        return "stale"
    end
    local first_output = 11 + nfields * 2
    if nfields > 0 then
        local fields = {}
        for i = 11, first_output - 1 do
            fields[#fields + 1] = ARGV[i]
        end
        redis.call("hset", job, unpack(fields))
    end
    if status == "done" then
        local outputs, size = {}, 0
        for i = first_output, #ARGV, 2 do
            outputs[#outputs + 1] = ARGV[i]
            outputs[#outputs + 1] = ARGV[i + 1]
            size = size + #ARGV[i + 1]
        end
        local out = out_key(id)
        redis.call("del", out)
        redis.call("hset", out, unpack(outputs))
        -- A backstop: expiry proper is the "expire" command, which keeps the counters right.
        redis.call("pexpire", out, ttl_ms + 60000)
        redis.call("zadd", kept, now, id)
        redis.call("hset", kept_size, id, size)
        redis.call("hincrby", stats, "kept_bytes", size)
        redis.call("hincrby", stats, "pixels_total", pixels)
    end
    finalize(id, status, now, limit)
    if status == "done" then
        while redis.call("zcard", kept) > max_count do
            drop_results(redis.call("zrange", kept, 0, 0)[1])
        end
        while redis.call("zcard", kept) > 0
            and tonumber(redis.call("hget", stats, "kept_bytes") or "0") > max_bytes do
            drop_results(redis.call("zrange", kept, 0, 0)[1])
        end
    end
    return "finished"

elseif command == "cancel" then
    -- cancel ID NOW LIMIT: a queued job is final at once; a running one is flagged for its
    -- worker, which stops at its next progress report.
    local id = ARGV[2]
    local job = job_key(id)
    local status = redis.call("hget", job, "status")
    if not status then
        return "gone"
    end
    if status == "queued" or status == "running" then
        redis.call("hset", job, "cancel", "1")
    end
    if status == "queued" then
        finalize(id, "cancelled", ARGV[3], tonumber(ARGV[4]))
    end
    return status

elseif command == "expire" then
    -- expire OLDEST_KEPT: drop the results of jobs finished at or before OLDEST_KEPT.
    local old = redis.call("zrangebyscore", kept, "-inf", ARGV[2])
    for _, id in ipairs(old) do
        drop_results(id)
    end
    return #old

elseif command == "sent" then
    -- sent ID: the job's message is in the queue.
    if redis.call("hget", job_key(ARGV[2]), "status") then
        redis.call("hset", job_key(ARGV[2]), "sent", "1")
    end
    return "ok"

elseif command == "orphans" then
    -- orphans CREATED_BEFORE: queued jobs whose message was never sent (their replica died
    -- between writing the job and sending it). The caller sends one for each; a message sent
    -- twice is harmless, as a second delivery of a started job is dropped.
    local found = {}
    for _, id in ipairs(redis.call("smembers", queued)) do
        local sent, created = unpack(redis.call("hmget", job_key(id), "sent", "created"))
        if sent ~= "1" and created and tonumber(created) < tonumber(ARGV[2]) then
            redis.call("hset", job_key(id), "sent", "1")
            found[#found + 1] = id
        end
    end
    return found

elseif command == "heartbeat" then
    -- heartbeat WORKER NOW STALE_BEFORE -> workers alive
    redis.call("zadd", workers, ARGV[3], ARGV[2])
    redis.call("zremrangebyscore", workers, "-inf", ARGV[4])
    return redis.call("zcard", workers)

elseif command == "leave" then
    redis.call("zrem", workers, ARGV[2])
    return "ok"
end

return redis.error_reply("unknown command " .. tostring(command))
