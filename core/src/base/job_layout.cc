#include "motionpipe/base/job_layout.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>

namespace motionpipe::layout {

namespace {
constexpr const char* kTaskDirPrefix = "task-";
}  // namespace

std::string TaskDirName(int64_t index) {
  char name[32];
  std::snprintf(name, sizeof(name), "%s%05lld", kTaskDirPrefix, static_cast<long long>(index));
  return name;
}

std::string TaskDir(const std::string& stage_dir, int64_t index) {
  return stage_dir + "/" + TaskDirName(index);
}

std::vector<std::string> StageOutputDirs(const std::string& stage_dir) {
  namespace fs = std::filesystem;
  std::vector<std::string> tasks;
  bool result = false;
  std::error_code ec;
  for (fs::directory_iterator it(stage_dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (!it->is_directory(ec)) continue;
    if (name == kResultDirName) result = true;
    if (name.rfind(kTaskDirPrefix, 0) == 0) tasks.push_back(it->path().string());
  }
  std::sort(tasks.begin(), tasks.end());
  if (result) tasks.insert(tasks.begin(), stage_dir + "/" + kResultDirName);
  if (tasks.empty()) tasks.push_back(stage_dir);
  return tasks;
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
