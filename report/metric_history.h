// The evaluation history (issue 9): every scored run of an evaluation stage appends its headline
// metrics to a SQLite file with the checkpoint and the hashes of the model config and of the
// evaluated data; a metric that falls more than a margin below its best earlier value for the same
// method is a regression. Several workers may append to one file (WAL, busy timeout).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe::report {

struct MetricRecord {
  std::string method;  // e.g. "mdt_editor/mdt"
  std::string metric;  // e.g. "generated_to_target.R@1"
  double value = 0;
  bool higher_is_better = true;
  std::string checkpoint, config_hash, data_hash, job;
  int64_t time_unix = 0;
};

struct Regression {
  std::string method, metric;
  double value = 0, best = 0, margin = 0;
  std::string best_checkpoint;
  std::string Describe() const;
};

// Appends the records to the history at `path` (created if missing) and returns the ones that
// regressed against the best earlier record of the same method and metric: lower than best - margin
// (or higher than best + margin when lower is better). The comparison uses only earlier records.
Result<std::vector<Regression>> AppendAndCompare(const std::string& path,
                                                 const std::vector<MetricRecord>& records,
                                                 double margin);

// Every record of the history at `path`, oldest first (the report's history plots).
Result<std::vector<MetricRecord>> ReadHistory(const std::string& path);

// A short stable hash (FNV-1a 64, hex) of a file's bytes, or of a string.
std::string HashText(const std::string& text);

}  // namespace motionpipe::report
