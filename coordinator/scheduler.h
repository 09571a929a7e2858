// The coordinator's state machine: jobs, stages, tasks, attempts (leases) and workers. No sockets
// here: the server feeds events in (worker ready/seen/lost, task results, ticks, submissions) and
// sends the messages that come out (assignments, cancels). Everything durable goes through the
// Journal; time comes from an injectable clock, so every failure class can be tested in-process.
//
// Failure classes (ARCHITECTURE.md):
//  - worker lost: its leases are re-queued; the retry budget is untouched (the loss is counted for
//    poison detection);
//  - task error: retried with exponential backoff up to max_attempts (a lease that expires on a
//  live
//    but slow worker counts as an error, and the task moves on to another worker);
//  - bad input: the task fails at once with the reason;
//  - poison: a task that loses `poison_threshold` workers is quarantined and its job fails with the
//    report.
// Outputs: an attempt writes into a staging directory; the first OK result renames it into place
// (first commit wins), later duplicates are discarded, so a task that ran twice leaves one output.
#pragma once

#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <queue>
#include <set>
#include <string>
#include <vector>

#include "journal.h"
#include "motionpipe.pb.h"
#include "pipeline.h"

namespace motionpipe::coordinator {

class Clock {
 public:
  virtual ~Clock() = default;
  virtual double Now() const = 0;  // unix seconds
};
class SystemClock : public Clock {
 public:
  double Now() const override;
};
class FakeClock : public Clock {
 public:
  explicit FakeClock(double now) : now_(now) {}
  double Now() const override { return now_; }
  void Advance(double seconds) { now_ += seconds; }

 private:
  double now_;
};

struct SchedulerOptions {
  double heartbeat_seconds = 1.0;
  int liveness = 3;  // missed heartbeats before a worker is lost
  // A task leased to a busy worker (queued behind its running one) for this long is reclaimed for
  // a worker that is idle: prefetching pays for millisecond tasks and must not cost worker-hours
  // when the tasks are long (issue 17's head-of-line blocking).
  double reclaim_after_seconds = 1.0;
};

// A message the server must send to a worker (identified by its routing identity).
struct Outgoing {
  std::string identity;
  std::optional<wire::Assign> assign;
  std::optional<wire::Cancel> cancel;
};

struct SchedulerCounters {
  int64_t committed = 0, errors = 0, failed = 0, lost = 0, quarantined = 0, handed_back = 0,
          lease_expired = 0;
  int64_t duplicates = 0, workers_lost = 0, bytes_committed = 0;
};

class Scheduler {
 public:
  Scheduler(Journal* journal, const Clock* clock, KindRegistry kinds, SchedulerOptions options);

  // Restores every unfinished job and the schedules from the journal.
  Status Resume();

  // Validates and plans the pipeline, journals the job; returns its id. A pipeline with `schedule:`
  // is registered as a recurring schedule instead (returns 0, the first run happens at its time)
  // unless `run_now`.
  Result<int64_t> Submit(const std::string& yaml, const std::vector<std::string>& overrides,
                         const std::string& origin, bool run_now = false);
  Status Cancel(int64_t job_id);

  // Workers.
  void OnReady(const std::string& identity, const wire::Ready& ready);
  void OnSeen(const std::string& identity);
  void OnDrain(const std::string& identity);
  void OnDisconnect(const std::string& identity);
  bool KnowsWorker(const std::string& identity) const { return workers_.count(identity) > 0; }

  // A result from `identity` (which may differ from the worker that got the lease, after
  // reconnects).
  void OnResult(const std::string& identity, const wire::TaskResult& result);

  // Time passes: lease expiry, dead workers, backoff release, schedules. Then dispatch.
  void Tick();
  // Fills every worker's free credit with ready tasks.
  void Dispatch();
  // Messages produced since the last call.
  std::vector<Outgoing> TakeOutgoing();
  // Workers that went silent for liveness * heartbeat and were dropped since the last call.
  std::vector<std::string> TakeLostWorkers();

  Status FlushJournal() { return journal_->Flush(); }
  size_t journal_backlog() const { return journal_->buffered(); }

  // Status for the control API.
  std::vector<wire::JobStatus> JobStatuses(int64_t job_id) const;
  std::vector<wire::WorkerStatus> WorkerStatuses() const;
  const SchedulerCounters& counters() const { return counters_; }
  int64_t pending_tasks() const;
  size_t live_workers() const { return workers_.size(); }
  bool AllJobsFinished() const;
  // The job's state ("" if unknown); for `wait`.
  std::string JobState(int64_t job_id) const;

 private:
  struct Attempt {
    int64_t id;
    int64_t job;
    size_t stage;
    int task;
    std::string identity;
    double started;
    double deadline;
    bool expired = false;
    bool reclaiming = false;  // asked back (only if still queued) for an idle worker
  };
  struct Task {
    TaskState state = TaskState::kPending;
    int live_attempts = 0;
    int errors = 0;
    int lost = 0;
    double not_before = 0;
    std::string message;
    std::vector<OutputRecord> outputs;
  };
  struct Stage {
    StageSpec spec;
    std::vector<Task> tasks;  // shards, then the reduce task if any
    int committed = 0, failed = 0, running = 0;
    std::deque<int> ready;  // pending tasks that may start now
    std::set<int> waiting;  // pending tasks held back (backoff, or a reduce before its shards)
    std::deque<double> commit_times;  // recent commits, for throughput and ETA
    std::vector<std::string> failures;
    bool started = false;
    bool dir_synced = false;  // its directory's entry in the job's is durable (first commit)
    bool gang() const { return spec.world_size > 1; }
  };
  struct Job {
    int64_t id;
    PipelineSpec spec;
    std::string state = "pending";
    double created = 0, finished = 0;
    std::string output_dir;
    std::string error;
    std::vector<Stage> stages;
  };
  struct Worker {
    std::string identity;
    wire::Ready ready;
    std::set<std::string> kinds;
    std::set<int64_t> attempts;
    double last_seen = 0;
    bool draining = false;
    int64_t done = 0;
  };

  Result<int64_t> CreateJob(const PipelineSpec& spec);
  void BuildStages(Job* job);
  bool StageRunnable(const Job& job, size_t stage) const;
  bool InputsDone(const Job& job, const Stage& stage) const;
  void Enqueue(Job* job, size_t stage, int task);
  std::optional<int> TakeReady(Job* job, size_t stage);
  void Assign(Worker* worker, Job* job, size_t stage, int task, const std::string& rendezvous = "");
  // Gangs: all ranks start together on distinct workers; a failing rank stops its gang.
  void DispatchGangs();
  // Asks busy workers to hand back tasks queued behind their running one, for idle workers.
  void ReclaimForIdleWorkers();
  // The first runnable ready task of any running job that `worker` can run, assigned; false if
  // none.
  bool AssignOne(Worker* worker);
  void StopGang(Job* job, size_t stage, int failed_rank, const std::string& why);
  void Commit(Job* job, size_t stage, int task, const Attempt& attempt,
              const wire::TaskResult& result);
  void TaskError(Job* job, size_t stage, int task, const std::string& message, bool bad_input);
  void TaskLost(Job* job, size_t stage, int task, const std::string& message);
  void StageProgress(Job* job, size_t stage);
  void FinishJob(Job* job, const std::string& state, const std::string& error);
  void ReleaseAttempt(int64_t attempt_id);
  void DropWorker(const std::string& identity, const std::string& reason);
  void FireSchedules();
  std::string TaskDir(const Job& job, const Stage& stage, int task) const;
  std::string StagingDir(const Job& job, const Stage& stage, int task, int64_t attempt) const;
  wire::TaskSpec MakeSpec(const Job& job, size_t stage, int task, int64_t attempt) const;
  Job* FindJob(int64_t id);

  Journal* journal_;
  const Clock* clock_;
  KindRegistry kinds_;
  SchedulerOptions options_;
  std::map<int64_t, Job> jobs_;
  std::map<std::string, Worker> workers_;
  std::map<int64_t, Attempt> attempts_;
  int64_t next_attempt_ = 1;
  std::vector<Outgoing> outgoing_;
  std::vector<std::string> lost_workers_;
  std::vector<StoredSchedule> schedules_;
  SchedulerCounters counters_;
};

}  // namespace motionpipe::coordinator
