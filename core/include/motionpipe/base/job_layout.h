// One home for the on-disk names of a job, in the spirit of LevelDB's db/filename.h. A job's output
// directory holds one directory per stage; a stage holds task-00000, task-00001, ... (and
// result/ for a reduce); a train task holds its checkpoint (model/), each rank's summary and rank
// 0's loss curves; an evaluation task holds its scores. Every stage, plugin, command and the report
// name these files through these functions, never as string literals.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace motionpipe::layout {

// "task-00000": the directory name of a stage's task `index`.
std::string TaskDirName(int64_t index);
// <stage_dir>/task-<index>.
std::string TaskDir(const std::string& stage_dir, int64_t index = 0);
// "result": a reduce stage's combined output.
inline constexpr const char* kResultDirName = "result";
// A stage's output directories in the order a stage's inputs list them: <stage_dir>/result first,
// then its task directories in name order; <stage_dir> itself when it holds neither (a task
// directory, or a user's folder, given directly).
std::vector<std::string> StageOutputDirs(const std::string& stage_dir);

// A checkpoint: <task_dir>/model, holding model.json (plugin name and config) and model.pt.
std::string CheckpointDir(const std::string& task_dir);
std::string ModelConfigFile(const std::string& checkpoint_dir);
std::string ModelWeightsFile(const std::string& checkpoint_dir);
// A train task's files: rank r's summary (rank-<r>.json); rank 0's training and validation loss
// per step.
std::string RankSummaryFile(const std::string& task_dir, int rank);
std::string LossesFile(const std::string& dir);
std::string ValLossesFile(const std::string& dir);
// An evaluation task's scores; the showcase stage's panels.
std::string MetricsFile(const std::string& task_dir);
std::string ShowcaseFile(const std::string& task_dir);

}  // namespace motionpipe::layout
