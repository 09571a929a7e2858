// A worker process: connects a DEALER to the coordinator's ROUTER, announces its capabilities
// (READY: stage kinds, threads, credit), and runs the tasks it is leased.
//  - An I/O thread owns the socket: it heartbeats both ways (any traffic counts; a long task never
//    looks dead), notices a silent coordinator and reconnects with exponential backoff under a new
//    routing identity, and keeps results produced while disconnected for the next connection.
//  - An executor thread runs tasks one at a time with the configured thread budget
//    (threads x workers <= cores); prefetched tasks (credit) wait in a queue.
//  - SIGTERM drains (what Slurm and Kubernetes send on preemption): no new tasks, queued tasks are
//    handed back, the running one finishes within the drain timeout or is handed back, then exit.
#pragma once

#include <atomic>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe::worker {

struct WorkerOptions {
  std::string coordinator = "tcp://127.0.0.1:5555";
  std::string name;  // default: hostname:pid
  int threads = 1;   // thread budget of one task
  int credit = 2;    // tasks leased at once (1 running + prefetched)
  double heartbeat_seconds = 1.0;
  int liveness = 3;
  double reconnect_max_seconds = 30;
  double drain_timeout_seconds = 30;
  std::vector<std::string> plugin_dirs;  // searched in addition to the defaults
  std::string metrics_bind;              // "127.0.0.1:9101"; empty = no /metrics
  std::string curve_keys;                // this worker's key file (enables CURVE)
  std::string server_key;                // the coordinator's public key (Z85 or key file)
};

// Makes every thread of this process allocate from glibc's main heap (M_ARENA_MAX 1); call it
// first in a worker process, before any thread starts (an arena, once a thread has one, stays its
// own). Otherwise the executor thread gets an arena of its own, made of 64 MiB heaps that glibc
// unmaps as soon as they are free again whatever the trim threshold, and maps anew at the next
// step: a model's activations then fault in fresh zeroed pages at every step (a TMR judge spent a
// sixth of its time in the kernel). With one heap, the plugins' trim threshold keeps freed memory
// for the next step (plugins/common/threads.h). README "Training in one heap" has the measurement.
// The price: threads that allocate at once share the heap's lock (a corpus task on 2 threads in a
// worker ran 1.4x slower). The environment overrides it: with MALLOC_ARENA_MAX or
// glibc.malloc.arena_max in GLIBC_TUNABLES set, glibc's setting stays and this returns false, as it
// does when glibc refuses.
bool UseMainHeapOnly();

// Runs until `*stop` (returns when the work is handed back or done), or until SIGTERM/SIGINT when
// `handle_signals`. Returns a non-ok Status only for setup errors (bad keys, metrics port taken).
Status RunWorker(const WorkerOptions& options, std::atomic<bool>* stop, bool handle_signals);

}  // namespace motionpipe::worker
