#include "metric_history.h"

#include <sqlite3.h>

#include <cstdio>
#include <memory>

namespace motionpipe::report {

namespace {

struct Db {
  sqlite3* db = nullptr;
  ~Db() {
    if (db) sqlite3_close(db);
  }
};

struct Statement {
  sqlite3_stmt* stmt = nullptr;
  ~Statement() {
    if (stmt) sqlite3_finalize(stmt);
  }
};

}  // namespace

std::string Regression::Describe() const {
  char text[512];
  std::snprintf(text, sizeof text,
                "%s %s regressed: %.4g against its best %.4g (margin %.4g, best checkpoint %s)",
                method.c_str(), metric.c_str(), value, best, margin, best_checkpoint.c_str());
  return text;
}

std::string HashText(const std::string& text) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ull;
  char out[17];
  std::snprintf(out, sizeof out, "%016llx", static_cast<unsigned long long>(h));
  return out;
}

Result<std::vector<Regression>> AppendAndCompare(const std::string& path,
                                                 const std::vector<MetricRecord>& records,
                                                 double margin) {
  Db db;
  if (sqlite3_open_v2(path.c_str(), &db.db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) !=
      SQLITE_OK) {
    return IoError(path + ": cannot open the evaluation history: " +
                   (db.db ? sqlite3_errmsg(db.db) : "out of memory"));
  }
  sqlite3_busy_timeout(db.db, 10000);
  const auto exec = [&](const char* sql) -> Status {
    char* error = nullptr;
    if (sqlite3_exec(db.db, sql, nullptr, nullptr, &error) != SQLITE_OK) {
      const std::string message = error ? error : "unknown error";
      sqlite3_free(error);
      return DataLoss(path + ": " + message);
    }
    return Status::Ok();
  };
  MP_RETURN_IF_ERROR(exec("PRAGMA journal_mode=WAL"));
  MP_RETURN_IF_ERROR(exec(
      "CREATE TABLE IF NOT EXISTS history (id INTEGER PRIMARY KEY, time INTEGER, job TEXT, method "
      "TEXT, metric TEXT, "
      "value REAL, higher_is_better INTEGER, checkpoint TEXT, config_hash TEXT, data_hash TEXT)"));
  MP_RETURN_IF_ERROR(exec("BEGIN IMMEDIATE"));
  std::vector<Regression> regressions;
  for (const MetricRecord& r : records) {
    Statement best;
    const char* query = r.higher_is_better ? "SELECT value, checkpoint FROM history WHERE method = "
                                             "? AND metric = ? ORDER BY value DESC LIMIT 1"
                                           : "SELECT value, checkpoint FROM history WHERE method = "
                                             "? AND metric = ? ORDER BY value ASC LIMIT 1";
    if (sqlite3_prepare_v2(db.db, query, -1, &best.stmt, nullptr) != SQLITE_OK)
      return DataLoss(path + ": " + sqlite3_errmsg(db.db));
    sqlite3_bind_text(best.stmt, 1, r.method.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(best.stmt, 2, r.metric.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(best.stmt) == SQLITE_ROW) {
      const double value = sqlite3_column_double(best.stmt, 0);
      const unsigned char* checkpoint = sqlite3_column_text(best.stmt, 1);
      const bool worse = r.higher_is_better ? r.value < value - margin : r.value > value + margin;
      if (worse)
        regressions.push_back({r.method, r.metric, r.value, value, margin,
                               checkpoint ? reinterpret_cast<const char*>(checkpoint) : ""});
    }
    Statement insert;
    if (sqlite3_prepare_v2(db.db,
                           "INSERT INTO history (time, job, method, metric, value, "
                           "higher_is_better, checkpoint, config_hash, data_hash) "
                           "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                           -1, &insert.stmt, nullptr) != SQLITE_OK) {
      return DataLoss(path + ": " + sqlite3_errmsg(db.db));
    }
    sqlite3_bind_int64(insert.stmt, 1, r.time_unix);
    sqlite3_bind_text(insert.stmt, 2, r.job.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(insert.stmt, 3, r.method.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(insert.stmt, 4, r.metric.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_double(insert.stmt, 5, r.value);
    sqlite3_bind_int(insert.stmt, 6, r.higher_is_better ? 1 : 0);
    sqlite3_bind_text(insert.stmt, 7, r.checkpoint.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(insert.stmt, 8, r.config_hash.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(insert.stmt, 9, r.data_hash.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(insert.stmt) != SQLITE_DONE) {
      (void)exec("ROLLBACK");
      return DataLoss(path + ": " + sqlite3_errmsg(db.db));
    }
  }
  MP_RETURN_IF_ERROR(exec("COMMIT"));
  return regressions;
}

Result<std::vector<MetricRecord>> ReadHistory(const std::string& path) {
  Db db;
  if (sqlite3_open_v2(path.c_str(), &db.db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    return IoError(path + ": cannot open the evaluation history: " +
                   (db.db ? sqlite3_errmsg(db.db) : "out of memory"));
  }
  sqlite3_busy_timeout(db.db, 10000);
  Statement rows;
  if (sqlite3_prepare_v2(db.db,
                         "SELECT time, job, method, metric, value, higher_is_better, checkpoint, "
                         "config_hash, data_hash FROM history ORDER BY id",
                         -1, &rows.stmt, nullptr) != SQLITE_OK) {
    return DataLoss(path + ": not an evaluation history: " + sqlite3_errmsg(db.db));
  }
  const auto text = [&](int column) {
    const unsigned char* value = sqlite3_column_text(rows.stmt, column);
    return value ? std::string(reinterpret_cast<const char*>(value)) : std::string();
  };
  std::vector<MetricRecord> out;
  int rc;
  while ((rc = sqlite3_step(rows.stmt)) == SQLITE_ROW) {
    MetricRecord r;
    r.time_unix = sqlite3_column_int64(rows.stmt, 0);
    r.job = text(1), r.method = text(2), r.metric = text(3);
    r.value = sqlite3_column_double(rows.stmt, 4);
    r.higher_is_better = sqlite3_column_int(rows.stmt, 5) != 0;
    r.checkpoint = text(6), r.config_hash = text(7), r.data_hash = text(8);
    out.push_back(std::move(r));
  }
  if (rc != SQLITE_DONE) return DataLoss(path + ": " + sqlite3_errmsg(db.db));
  return out;
}

}  // namespace motionpipe::report
