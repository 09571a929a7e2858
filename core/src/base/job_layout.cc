#include "motionpipe/base/job_layout.h"

#include <cstdio>

namespace motionpipe::layout {

std::string TaskDirName(int64_t index) {
  char name[32];
  std::snprintf(name, sizeof(name), "task-%05lld", static_cast<long long>(index));
  return name;
}

std::string TaskDir(const std::string& stage_dir, int64_t index) {
  return stage_dir + "/" + TaskDirName(index);
}

std::string CheckpointDir(const std::string& task_dir) { return task_dir + "/model"; }
std::string ModelConfigFile(const std::string& checkpoint_dir) {
  return checkpoint_dir + "/model.json";
}
std::string ModelWeightsFile(const std::string& checkpoint_dir) {
  return checkpoint_dir + "/model.pt";
}

std::string RankSummaryFile(const std::string& task_dir, int rank) {
  return task_dir + "/rank-" + std::to_string(rank) + ".json";
}
std::string LossesFile(const std::string& dir) { return dir + "/losses.csv"; }
std::string ValLossesFile(const std::string& dir) { return dir + "/val_losses.csv"; }

std::string MetricsFile(const std::string& task_dir) { return task_dir + "/metrics.json"; }
std::string ShowcaseFile(const std::string& task_dir) { return task_dir + "/showcase.json"; }

}  // namespace motionpipe::layout
