// Pipeline YAML: named stages with a kind, inputs, params, sharding, retries and resources; the
// stages form a DAG by their inputs. Command-line overrides `key.sub=value` (the Hydra habit) and
// `${vars.name}` interpolation are applied before validation; an invalid pipeline is rejected
// before anything runs, with the YAML path of each error.
//
//   name: demo                      # required
//   output_root: out                # job outputs go to <output_root>/<name>-<job id>/
//   seed: 1
//   schedule: "0 3 * * *"           # optional cron: the job recurs
//   vars: {steps: 300}              # free values for ${vars.steps}
//   scale: small                    # picks scales.small, vars that override `vars` (the override
//   scales: {small: {steps: 80}, paper: {steps: 20000}}   # scale=paper picks another)
//   defaults: {max_attempts: 3, retry_backoff: 2s, timeout: 1h, poison_threshold: 3, threads: 1}
//   stages:
//     corpus:  {kind: corpus, params: {clips: 1500}}
//     filter:  {kind: filter, inputs: [corpus], shards: 8, params: {...}}
//     mdt:     {kind: train, inputs: [filter], seeds: 3, params: {...}}   # mdt, mdt-s2, mdt-s3
//   targets: [mdt]                  # optional: only these stages and what they need run
//
// A file may instead derive from another: `base: ../claims_edit.yaml` plus its own name and the
// keys it changes (ReadPipelineFile below); `stages: {mdm: null}` drops a stage of the base.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "executor.h"
#include "motionpipe/base/status.h"

namespace motionpipe::coordinator {

// The most tasks one job may plan (the dispatch benchmark runs 200,000 no-op tasks).
inline constexpr int64_t kMaxJobTasks = 1000000;

struct StageSpec {
  std::string name;
  std::string kind;
  std::vector<std::string> inputs;
  nlohmann::json params = nlohmann::json::object();
  int shards = 1;  // map tasks
  bool shards_set =
      false;  // `shards:` given in the YAML (planners may pick their own default otherwise)
  bool reduce = false;                 // plus one reduce task after all shards committed
  int max_attempts = 3;                // task errors tolerated before the task fails
  double retry_backoff_seconds = 1.0;  // doubled after each error
  double timeout_seconds = 3600;       // lease of one attempt
  bool timeout_set = false;            // `timeout:` given (stage or defaults): kinds keep it
  int poison_threshold = 3;            // a task that loses this many workers is quarantined
  int threads = 0;                     // per task; 0 = the worker's budget
  int world_size = 1;                  // gang size (training)
  int replicate = 1;                   // k of `seeds: N` (the stage is named name-sk for k > 1)
};

struct PipelineSpec {
  std::string name;
  std::string output_root = "out";
  uint64_t seed = 1;
  std::string schedule;
  std::vector<StageSpec> stages;  // topological order
  std::string resolved;           // JSON after overrides and interpolation: what the journal keeps
  std::string fingerprint;        // sha256 of `resolved`: the same pipeline, resumed or reused
};

using worker::StagePlanner;

// Kinds the coordinator can plan: the built-in ones and those that plugins declare. A kind's
// planner is its executor's Plan (stages/), so planning and running a kind live together.
class KindRegistry {
 public:
  // Every built-in kind (stages/): each planned by its executor, plus the planner-only kinds
  // (`train`, run by the train plugin).
  static KindRegistry WithBuiltins();
  // The kinds of `executors`, each planned by its executor (kept alive by the registry).
  static KindRegistry FromExecutors(std::shared_ptr<const worker::ExecutorRegistry> executors);
  void Add(const std::string& kind, StagePlanner planner);
  // Kinds from a plugin: sharded by `shards:` (default 1) and `reduce:`.
  void AddGeneric(const std::string& kind);
  const StagePlanner* Find(const std::string& kind) const;
  std::vector<std::string> Kinds() const;

 private:
  std::map<std::string, StagePlanner> planners_;
};

// Reads a pipeline file. A file with `base: PATH` (relative to the file's own directory) derives
// from that pipeline: it is a JSON merge patch (RFC 7386) over it, so maps merge key by key (vars,
// stages, a stage's params), null removes a key (a stage, a var) and anything else replaces (a
// list of inputs); bases may chain, and a derived file names itself. What comes back is
// self-contained, without `base`, as the journal keeps it; a file without `base` comes back as its
// own text (so a pipeline's fingerprint does not change with this reader).
Result<std::string> ReadPipelineFile(const std::string& path);

// Parses, overrides, interpolates, validates and plans. InvalidArgument lists every problem as
// "origin: path: message" lines.
Result<PipelineSpec> ParsePipeline(const std::string& yaml_text,
                                   const std::vector<std::string>& overrides,
                                   const std::string& origin, const KindRegistry& kinds);

// "90", "90s", "15m", "2h", "1d" -> seconds; false on anything else.
bool ParseDuration(const std::string& text, double* seconds);

}  // namespace motionpipe::coordinator
