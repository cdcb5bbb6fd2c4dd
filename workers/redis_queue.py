"""The Redis backend's queue: one waiting list per principal, served round-robin.

Jobs wait in one Redis list per principal (``segue:queue:<principal hash>``, the principal that
submitted them: :attr:`schemas.JobInfo.owner`; jobs without one, such as the server's own small
jobs, share one list). A worker with nothing to do runs :data:`TAKE_LUA`, atomically:

1. an entry already in the jobs stream that no worker has read (written there directly: an
   earlier version's API) is delivered first;
2. else it pops the next job of the *next principal* after the one served last (the lists that
   hold jobs are in ``segue:queues``, a sorted set read in name order from the cursor
   ``segue:queues:turn``, wrapping round), adds it to the jobs stream and reads it with
   ``XREADGROUP`` for this worker in the same script, so from there on it is an ordinary pending
   entry: heartbeats, reclaim after a worker's death, acks and dead letters are those of
   :mod:`workers.redis_worker`, unchanged.

So one principal's backlog delays another principal's next job by at most the job each worker is
running: whichever worker frees up first serves the other principal next. The stream holds only
the jobs being run. Idle workers wait on ``segue:queues:bell`` (``BLPOP``, one token pushed per
job queued) instead of polling. A job a worker gives back (its cache disk is full, or it is of
another version: :data:`RELEASE_LUA`) goes back to the *head* of its principal's list, acked and
removed from the stream in the same script.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from .redis_keys import RedisKeys

BELL_MAX = 1000
"""Most wake-up tokens kept for idle workers (one per queued job; more would only wake them)."""

SUBMIT_LUA = """
-- KEYS[1] the principal's list, KEYS[2] segue:queues, KEYS[3] the bell
-- ARGV[1] the entry (JSON), ARGV[2] 'head' to queue it first (a job given back), ARGV[3] bell max
if ARGV[2] == 'head' then redis.call('LPUSH', KEYS[1], ARGV[1]) else redis.call('RPUSH', KEYS[1], ARGV[1]) end
redis.call('ZADD', KEYS[2], 0, KEYS[1])
redis.call('LPUSH', KEYS[3], 1)
redis.call('LTRIM', KEYS[3], 0, tonumber(ARGV[3]) - 1)
return redis.call('LLEN', KEYS[1])
"""

TAKE_LUA = """
-- KEYS[1] segue:queues, KEYS[2] segue:queues:turn, KEYS[3] the jobs stream
-- ARGV[1] the group, ARGV[2] this consumer
-- returns {entry id, field, value, ...} or nil
local function read()
  local got = redis.call('XREADGROUP', 'GROUP', ARGV[1], ARGV[2], 'COUNT', 1, 'STREAMS', KEYS[3], '>')
  if got and got[1] and got[1][2][1] then
    local entry = got[1][2][1]
    local out = {entry[1]}
    for _, v in ipairs(entry[2]) do table.insert(out, v) end
    return out
  end
  return nil
end
local waiting = read()
if waiting then return waiting end
local turn = redis.call('GET', KEYS[2])
local order = {}
if turn then
  for _, k in ipairs(redis.call('ZRANGEBYLEX', KEYS[1], '(' .. turn, '+')) do table.insert(order, k) end
  for _, k in ipairs(redis.call('ZRANGEBYLEX', KEYS[1], '-', '[' .. turn)) do table.insert(order, k) end
else
  order = redis.call('ZRANGEBYLEX', KEYS[1], '-', '+')
end
for _, list in ipairs(order) do
  local item = redis.call('LPOP', list)
  if redis.call('LLEN', list) == 0 then redis.call('ZREM', KEYS[1], list) end
  if item then
    redis.call('SET', KEYS[2], list)
    local entry = cjson.decode(item)
    local fields = {}
    for k, v in pairs(entry) do
      table.insert(fields, k)
      table.insert(fields, tostring(v))
    end
    redis.call('XADD', KEYS[3], '*', unpack(fields))
    return read()
  end
end
return nil
"""

RELEASE_LUA = """
-- KEYS[1] the jobs stream, KEYS[2] the principal's list, KEYS[3] segue:queues, KEYS[4] the bell
-- ARGV[1] group, ARGV[2] this consumer, ARGV[3] entry id, ARGV[4] the entry (JSON), ARGV[5] bell max
-- gives a pending entry of ours back to its principal's list (first in it); 0 when not ours
local p = redis.call('XPENDING', KEYS[1], ARGV[1], ARGV[3], ARGV[3], 1)
if #p == 0 or p[1][2] ~= ARGV[2] then return 0 end
redis.call('XACK', KEYS[1], ARGV[1], ARGV[3])
redis.call('XDEL', KEYS[1], ARGV[3])
redis.call('LPUSH', KEYS[2], ARGV[4])
redis.call('ZADD', KEYS[3], 0, KEYS[2])
redis.call('LPUSH', KEYS[4], 1)
redis.call('LTRIM', KEYS[4], 0, tonumber(ARGV[5]) - 1)
return 1
"""


def principal_list(keys: RedisKeys, owner: str | None) -> str:
    """The waiting list of a principal's jobs (``owner`` None or empty: the shared one)."""
    digest = hashlib.sha256((owner or "").encode()).hexdigest()[:16]
    return keys.queue(digest)


def queue_entry(job_id: str, kind: str, payload: dict[str, Any], owner: str | None, **extra: str) -> str:
    """A waiting job as its principal's list holds it (JSON of the stream entry's fields, all
    strings): ``job``, ``kind``, ``payload`` (JSON), ``owner``, and ``extra`` fields (the job
    format and version stamps, a worker's give-back marks)."""
    fields = {"job": job_id, "kind": kind, "payload": json.dumps(payload), "owner": owner or "", **extra}
    return json.dumps(fields)


def entry_of_fields(fields: dict[str, str]) -> str:
    """A stream entry's fields as its principal's list holds them (a job given back)."""
    return json.dumps(dict(fields))
