// The coordinator's journal: jobs, their stages' tasks, committed outputs, and recurring schedules
// in SQLite (WAL). Job creation is committed at once; task and job state changes are buffered and
// written in one transaction per Flush() (the coordinator flushes every few milliseconds), so a job
// of tens of thousands of tasks costs a few transactions, not one per task. A coordinator killed
// with SIGKILL and restarted reloads every unfinished job: tasks journaled as committed are never
// run again.
#pragma once

#include <sqlite3.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe::coordinator {

enum class TaskState { kPending = 0, kCommitted = 1, kFailed = 2, kQuarantined = 3 };
const char* TaskStateName(TaskState state);

struct OutputRecord {
  std::string path;  // relative to the task's output directory
  std::string sha256;
  int64_t bytes = 0;
};

struct StoredTask {
  std::string stage;
  int index = 0;
  TaskState state = TaskState::kPending;
  int errors = 0;
  int lost = 0;
  std::string message;
  std::vector<OutputRecord> outputs;
};

struct StoredJob {
  int64_t id = 0;
  std::string name;
  std::string pipeline;  // resolved JSON
  std::string fingerprint;
  std::string state;  // pending, running, succeeded, failed, cancelled
  double created = 0, finished = 0;
  std::string output_dir;
  std::string error;
  std::vector<StoredTask> tasks;
};

struct StoredSchedule {
  int64_t id = 0;
  std::string name;
  std::string pipeline;  // resolved JSON
  std::string cron;
  int64_t next_fire = 0;  // unix seconds
};

class Journal {
 public:
  // Opens (creating when needed) the journal at `path`; ":memory:" for tests.
  static Result<std::unique_ptr<Journal>> Open(const std::string& path);
  ~Journal();

  // Inserts the job and all its tasks (pending) in one committed transaction; returns the job id.
  Result<int64_t> CreateJob(const StoredJob& job);
  // Buffered until Flush().
  void UpdateTask(int64_t job, const std::string& stage, int index, TaskState state, int errors,
                  int lost, const std::string& message);
  void AddOutputs(int64_t job, const std::string& stage, int index,
                  const std::vector<OutputRecord>& outputs);
  void UpdateJob(int64_t job, const std::string& state, double finished, const std::string& error);
  // Commits every buffered change in one transaction. IoError on failure (the buffer is kept).
  Status Flush();
  size_t buffered() const { return ops_.size(); }

  // Jobs whose state is pending or running, with their tasks and outputs.
  Result<std::vector<StoredJob>> LoadUnfinished();
  // Every job (without tasks), newest first, for status listings.
  Result<std::vector<StoredJob>> ListJobs(int limit);

  // A fresh block number for this coordinator run (persisted, strictly increasing): attempt ids are
  // block << 32 | n, so a late result from before a restart can never match a new attempt.
  Result<int64_t> NextAttemptBlock();

  Result<int64_t> AddSchedule(const StoredSchedule& schedule);
  Status SetScheduleNextFire(int64_t id, int64_t next_fire);
  Result<std::vector<StoredSchedule>> LoadSchedules();

 private:
  explicit Journal(sqlite3* db) : db_(db) {}
  Status Exec(const std::string& sql);

  struct Op {
    int kind;  // 0 task, 1 outputs, 2 job
    int64_t job;
    std::string stage;
    int index;
    int state;
    int errors, lost;
    std::string text;
    double number;
    std::vector<OutputRecord> outputs;
  };
  sqlite3* db_;
  std::vector<Op> ops_;
  sqlite3_stmt* update_task_ = nullptr;
  sqlite3_stmt* insert_output_ = nullptr;
  sqlite3_stmt* update_job_ = nullptr;
};

}  // namespace motionpipe::coordinator
