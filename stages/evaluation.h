// What the evaluation stages share: scores and plausibility as JSON, previews, embeddings, the
// evaluation history and metrics.json.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "motionpipe/eval/metrics.h"
#include "motionpipe/motion/motion.h"
#include "stage.h"

namespace motionpipe::stages {

// The evaluation history (params.history: a SQLite file; off when absent): appends the tracked
// metrics, adds "regressions" to `metrics`, logs each one, and (fail_on_regression) fails the task,
// which fails the job: the exit code of `run` and `wait`. A regression is a metric more than
// params.regression_margin (absolute, in the metric's units) below its best earlier value.
struct Tracked {
  const char* name;
  double value;
  bool higher_is_better;
};

json ScoresJson(const eval::RetrievalScores& s);

// Physical plausibility averaged over motions: foot skating, floor penetration, floating, jerk.
json MeanPlausibility(const std::vector<Motion>& motions);

// preview.npz next to metrics.json: the first evaluated example's motions as clips (ids = roles:
// "source", "edited", "target"; "generated", "truth"), each with its text, for the report's
// renders.
Status WritePreview(const TaskContext& ctx,
                    const std::vector<std::pair<std::string, const Motion*>>& roles,
                    const std::string& text, const std::string& example);

// Cosine similarity of two embeddings (0 for a zero vector).
double Cosine(const std::vector<float>& a, const std::vector<float>& b);

// Embeddings from an encoder's rows.
eval::Embeddings ToEmbeddings(const std::vector<std::vector<float>>& rows);

// What an evaluated stage's summary (edits.json, generate.json) says: the model's name and
// checkpoint.
void ReadSummary(const std::string& path, std::string* method, std::string* checkpoint);

std::optional<TaskReport> RecordHistory(const TaskContext& ctx, json* metrics,
                                        const std::string& method, const std::string& checkpoint,
                                        const std::vector<std::string>& ids,
                                        const std::vector<Tracked>& tracked);

// The scoring's wall time (loading the evaluators, encoding, metrics) and its throughput in motions
// scored (generated and reference motions alike) per second: the evaluation benchmark reads these.
void AddTiming(json* metrics, std::chrono::steady_clock::time_point started, size_t motions_scored);

// Writes metrics.json; the task's report carries the number of regressions.
TaskReport WriteMetrics(const TaskContext& ctx, const json& metrics);

}  // namespace motionpipe::stages
