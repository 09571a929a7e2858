#include "journal.h"

#include <map>

namespace motionpipe::coordinator {

namespace {
constexpr char kSchema[] = R"sql(
CREATE TABLE IF NOT EXISTS jobs (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  name TEXT NOT NULL, pipeline TEXT NOT NULL, fingerprint TEXT NOT NULL,
  state TEXT NOT NULL, created REAL NOT NULL, finished REAL NOT NULL DEFAULT 0,
  output_dir TEXT NOT NULL, error TEXT NOT NULL DEFAULT '');
CREATE TABLE IF NOT EXISTS tasks (
  job INTEGER NOT NULL, stage TEXT NOT NULL, idx INTEGER NOT NULL,
  state INTEGER NOT NULL DEFAULT 0, errors INTEGER NOT NULL DEFAULT 0, lost INTEGER NOT NULL DEFAULT 0,
  message TEXT NOT NULL DEFAULT '',
  PRIMARY KEY (job, stage, idx)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS outputs (
  job INTEGER NOT NULL, stage TEXT NOT NULL, idx INTEGER NOT NULL,
  path TEXT NOT NULL, sha256 TEXT NOT NULL, bytes INTEGER NOT NULL);
CREATE INDEX IF NOT EXISTS outputs_task ON outputs (job, stage, idx);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS schedules (
  id INTEGER PRIMARY KEY AUTOINCREMENT, name TEXT NOT NULL, pipeline TEXT NOT NULL,
  cron TEXT NOT NULL, next_fire INTEGER NOT NULL);
)sql";

std::string Text(sqlite3_stmt* stmt, int column) {
  const auto* text = sqlite3_column_text(stmt, column);
  return text ? reinterpret_cast<const char*>(text) : "";
}
}  // namespace

const char* TaskStateName(TaskState state) {
  switch (state) {
    case TaskState::kPending:
      return "pending";
    case TaskState::kCommitted:
      return "committed";
    case TaskState::kFailed:
      return "failed";
    case TaskState::kQuarantined:
      return "quarantined";
  }
  return "unknown";
}

Result<std::unique_ptr<Journal>> Journal::Open(const std::string& path) {
  sqlite3* db = nullptr;
  if (sqlite3_open(path.c_str(), &db) != SQLITE_OK) {
    const std::string reason = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    return IoError(path + ": cannot open journal: " + reason);
  }
  std::unique_ptr<Journal> journal(new Journal(db));
  sqlite3_busy_timeout(db, 5000);
  // WAL survives a killed process; NORMAL syncs at checkpoints (a power cut may lose the last
  // batch, a SIGKILL loses nothing that was committed).
  MP_RETURN_IF_ERROR(
      journal->Exec("PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;").WithContext(path));
  MP_RETURN_IF_ERROR(journal->Exec(kSchema).WithContext(path));
  const auto prepare = [&](const char* sql, sqlite3_stmt** stmt) -> Status {
    if (sqlite3_prepare_v2(db, sql, -1, stmt, nullptr) != SQLITE_OK)
      return Internal(path + ": " + sqlite3_errmsg(db));
    return Status::Ok();
  };
  MP_RETURN_IF_ERROR(prepare(
      "UPDATE tasks SET state=?, errors=?, lost=?, message=? WHERE job=? AND stage=? AND idx=?",
      &journal->update_task_));
  MP_RETURN_IF_ERROR(
      prepare("INSERT INTO outputs (job, stage, idx, path, sha256, bytes) VALUES (?,?,?,?,?,?)",
              &journal->insert_output_));
  MP_RETURN_IF_ERROR(
      prepare("UPDATE jobs SET state=?, finished=?, error=? WHERE id=?", &journal->update_job_));
  return journal;
}

Journal::~Journal() {
  sqlite3_finalize(update_task_);
  sqlite3_finalize(insert_output_);
  sqlite3_finalize(update_job_);
  sqlite3_close(db_);
}

Status Journal::Exec(const std::string& sql) {
  char* error = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error) != SQLITE_OK) {
    const std::string message = error ? error : "unknown error";
    sqlite3_free(error);
    return IoError("journal: " + message);
  }
  return Status::Ok();
}

Result<int64_t> Journal::CreateJob(const StoredJob& job) {
  MP_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db_,
                     "INSERT INTO jobs (name, pipeline, fingerprint, state, created, output_dir) "
                     "VALUES (?,?,?,?,?,?)",
                     -1, &stmt, nullptr);
  sqlite3_bind_text(stmt, 1, job.name.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(stmt, 2, job.pipeline.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(stmt, 3, job.fingerprint.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(stmt, 4, job.state.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_double(stmt, 5, job.created);
  sqlite3_bind_text(stmt, 6, job.output_dir.c_str(), -1, SQLITE_TRANSIENT);
  const int rc = sqlite3_step(stmt);
  sqlite3_finalize(stmt);
  if (rc != SQLITE_DONE) {
    Exec("ROLLBACK");
    return IoError(std::string("journal: cannot insert job: ") + sqlite3_errmsg(db_));
  }
  const int64_t id = sqlite3_last_insert_rowid(db_);
  sqlite3_prepare_v2(db_, "INSERT INTO tasks (job, stage, idx) VALUES (?,?,?)", -1, &stmt, nullptr);
  for (const StoredTask& task : job.tasks) {
    sqlite3_reset(stmt);
    sqlite3_bind_int64(stmt, 1, id);
    sqlite3_bind_text(stmt, 2, task.stage.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_int(stmt, 3, task.index);
    if (sqlite3_step(stmt) != SQLITE_DONE) {
      sqlite3_finalize(stmt);
      Exec("ROLLBACK");
      return IoError(std::string("journal: cannot insert tasks: ") + sqlite3_errmsg(db_));
    }
  }
  sqlite3_finalize(stmt);
  MP_RETURN_IF_ERROR(Exec("COMMIT"));
  return id;
}

void Journal::UpdateTask(int64_t job, const std::string& stage, int index, TaskState state,
                         int errors, int lost, const std::string& message) {
  ops_.push_back({0, job, stage, index, static_cast<int>(state), errors, lost, message, 0, {}});
}

void Journal::AddOutputs(int64_t job, const std::string& stage, int index,
                         const std::vector<OutputRecord>& outputs) {
  if (outputs.empty()) return;
  ops_.push_back({1, job, stage, index, 0, 0, 0, "", 0, outputs});
}

void Journal::UpdateJob(int64_t job, const std::string& state, double finished,
                        const std::string& error) {
  ops_.push_back({2, job, "", 0, 0, 0, 0, state + '\n' + error, finished, {}});
}

Status Journal::Flush() {
  if (ops_.empty()) return Status::Ok();
  MP_RETURN_IF_ERROR(Exec("BEGIN"));
  for (const Op& op : ops_) {
    int rc = SQLITE_DONE;
    if (op.kind == 0) {
      sqlite3_reset(update_task_);
      sqlite3_bind_int(update_task_, 1, op.state);
      sqlite3_bind_int(update_task_, 2, op.errors);
      sqlite3_bind_int(update_task_, 3, op.lost);
      sqlite3_bind_text(update_task_, 4, op.text.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_int64(update_task_, 5, op.job);
      sqlite3_bind_text(update_task_, 6, op.stage.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_int(update_task_, 7, op.index);
      rc = sqlite3_step(update_task_);
    } else if (op.kind == 1) {
      for (const OutputRecord& out : op.outputs) {
        sqlite3_reset(insert_output_);
        sqlite3_bind_int64(insert_output_, 1, op.job);
        sqlite3_bind_text(insert_output_, 2, op.stage.c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_int(insert_output_, 3, op.index);
        sqlite3_bind_text(insert_output_, 4, out.path.c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_text(insert_output_, 5, out.sha256.c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_int64(insert_output_, 6, out.bytes);
        rc = sqlite3_step(insert_output_);
        if (rc != SQLITE_DONE) break;
      }
    } else {
      const size_t newline = op.text.find('\n');
      const std::string state = op.text.substr(0, newline), error = op.text.substr(newline + 1);
      sqlite3_reset(update_job_);
      sqlite3_bind_text(update_job_, 1, state.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_double(update_job_, 2, op.number);
      sqlite3_bind_text(update_job_, 3, error.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_int64(update_job_, 4, op.job);
      rc = sqlite3_step(update_job_);
    }
    if (rc != SQLITE_DONE) {
      const std::string reason = sqlite3_errmsg(db_);
      Exec("ROLLBACK");
      return IoError("journal: write failed: " + reason);
    }
  }
  MP_RETURN_IF_ERROR(Exec("COMMIT"));
  ops_.clear();
  return Status::Ok();
}

Result<std::vector<StoredJob>> Journal::LoadUnfinished() {
  std::vector<StoredJob> jobs;
  std::map<int64_t, size_t> index;
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db_,
                     "SELECT id, name, pipeline, fingerprint, state, created, finished, "
                     "output_dir, error FROM jobs "
                     "WHERE state IN ('pending', 'running') ORDER BY id",
                     -1, &stmt, nullptr);
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    StoredJob job;
    job.id = sqlite3_column_int64(stmt, 0);
    job.name = Text(stmt, 1);
    job.pipeline = Text(stmt, 2);
    job.fingerprint = Text(stmt, 3);
    job.state = Text(stmt, 4);
    job.created = sqlite3_column_double(stmt, 5);
    job.finished = sqlite3_column_double(stmt, 6);
    job.output_dir = Text(stmt, 7);
    job.error = Text(stmt, 8);
    index[job.id] = jobs.size();
    jobs.push_back(std::move(job));
  }
  sqlite3_finalize(stmt);
  sqlite3_prepare_v2(
      db_,
      "SELECT job, stage, idx, state, errors, lost, message FROM tasks ORDER BY job, stage, idx",
      -1, &stmt, nullptr);
  std::map<std::tuple<int64_t, std::string, int>, std::pair<size_t, size_t>> task_index;
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    const auto it = index.find(sqlite3_column_int64(stmt, 0));
    if (it == index.end()) continue;
    StoredTask task;
    task.stage = Text(stmt, 1);
    task.index = sqlite3_column_int(stmt, 2);
    task.state = static_cast<TaskState>(sqlite3_column_int(stmt, 3));
    task.errors = sqlite3_column_int(stmt, 4);
    task.lost = sqlite3_column_int(stmt, 5);
    task.message = Text(stmt, 6);
    task_index[{it->first, task.stage, task.index}] = {it->second, jobs[it->second].tasks.size()};
    jobs[it->second].tasks.push_back(std::move(task));
  }
  sqlite3_finalize(stmt);
  sqlite3_prepare_v2(db_, "SELECT job, stage, idx, path, sha256, bytes FROM outputs", -1, &stmt,
                     nullptr);
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    const auto it = task_index.find(
        {sqlite3_column_int64(stmt, 0), Text(stmt, 1), sqlite3_column_int(stmt, 2)});
    if (it == task_index.end()) continue;
    jobs[it->second.first].tasks[it->second.second].outputs.push_back(
        {Text(stmt, 3), Text(stmt, 4), sqlite3_column_int64(stmt, 5)});
  }
  sqlite3_finalize(stmt);
  return jobs;
}

Result<std::vector<StoredJob>> Journal::ListJobs(int limit) {
  std::vector<StoredJob> jobs;
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db_,
                     "SELECT id, name, fingerprint, state, created, finished, output_dir, error "
                     "FROM jobs ORDER BY id DESC LIMIT ?",
                     -1, &stmt, nullptr);
  sqlite3_bind_int(stmt, 1, limit);
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    StoredJob job;
    job.id = sqlite3_column_int64(stmt, 0);
    job.name = Text(stmt, 1);
    job.fingerprint = Text(stmt, 2);
    job.state = Text(stmt, 3);
    job.created = sqlite3_column_double(stmt, 4);
    job.finished = sqlite3_column_double(stmt, 5);
    job.output_dir = Text(stmt, 6);
    job.error = Text(stmt, 7);
    jobs.push_back(std::move(job));
  }
  sqlite3_finalize(stmt);
  return jobs;
}

Result<int64_t> Journal::NextAttemptBlock() {
  MP_RETURN_IF_ERROR(
      Exec("INSERT INTO meta (key, value) VALUES ('attempt_block', 1) "
           "ON CONFLICT(key) DO UPDATE SET value = value + 1"));
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db_, "SELECT value FROM meta WHERE key = 'attempt_block'", -1, &stmt, nullptr);
  int64_t block = 0;
  if (sqlite3_step(stmt) == SQLITE_ROW) block = sqlite3_column_int64(stmt, 0);
  sqlite3_finalize(stmt);
  if (block <= 0) return IoError("journal: cannot allocate an attempt id block");
  return block;
}

Result<int64_t> Journal::AddSchedule(const StoredSchedule& schedule) {
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db_,
                     "INSERT INTO schedules (name, pipeline, cron, next_fire) VALUES (?,?,?,?)", -1,
                     &stmt, nullptr);
  sqlite3_bind_text(stmt, 1, schedule.name.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(stmt, 2, schedule.pipeline.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(stmt, 3, schedule.cron.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_int64(stmt, 4, schedule.next_fire);
  const int rc = sqlite3_step(stmt);
  sqlite3_finalize(stmt);
  if (rc != SQLITE_DONE)
    return IoError(std::string("journal: cannot add schedule: ") + sqlite3_errmsg(db_));
  return sqlite3_last_insert_rowid(db_);
}

Status Journal::SetScheduleNextFire(int64_t id, int64_t next_fire) {
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db_, "UPDATE schedules SET next_fire=? WHERE id=?", -1, &stmt, nullptr);
  sqlite3_bind_int64(stmt, 1, next_fire);
  sqlite3_bind_int64(stmt, 2, id);
  const int rc = sqlite3_step(stmt);
  sqlite3_finalize(stmt);
  if (rc != SQLITE_DONE)
    return IoError(std::string("journal: cannot update schedule: ") + sqlite3_errmsg(db_));
  return Status::Ok();
}

Result<std::vector<StoredSchedule>> Journal::LoadSchedules() {
  std::vector<StoredSchedule> schedules;
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db_, "SELECT id, name, pipeline, cron, next_fire FROM schedules ORDER BY id",
                     -1, &stmt, nullptr);
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    schedules.push_back({sqlite3_column_int64(stmt, 0), Text(stmt, 1), Text(stmt, 2), Text(stmt, 3),
                         sqlite3_column_int64(stmt, 4)});
  }
  sqlite3_finalize(stmt);
  return schedules;
}

}  // namespace motionpipe::coordinator
