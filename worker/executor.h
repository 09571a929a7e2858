// Stage executors: what a worker runs for each stage kind. Built-in kinds register here; plugins
// add theirs through the C ABI (plugin_host.h). A task writes its outputs into ctx.output_dir (the
// attempt's staging directory); the worker checksums every file there and the coordinator renames
// the directory into place on commit.
#pragma once

#include <atomic>
#include <functional>
#include <initializer_list>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe.pb.h"
#include "motionpipe/base/status.h"

namespace motionpipe::worker {

enum class Outcome { kOk, kError, kBadInput };

struct TaskReport {
  Outcome outcome = Outcome::kOk;
  std::string message;
  std::map<std::string, double> metrics;

  static TaskReport Ok() { return {}; }
  static TaskReport Error(std::string message) { return {Outcome::kError, std::move(message), {}}; }
  static TaskReport BadInput(std::string message) {
    return {Outcome::kBadInput, std::move(message), {}};
  }
  // The one mapping of a failed Status: deterministic input problems (invalid argument, not found,
  // data loss) fail the task at once as bad input; anything else may be transient and is retried.
  static TaskReport FromStatus(const Status& s);
};

struct TaskContext {
  wire::TaskSpec spec;
  nlohmann::json params;
  const std::atomic<int>* cancel = nullptr;
  int threads = 1;
  // Set by the worker: live metric values (exposed on /metrics while the task runs).
  std::function<void(const std::string&, double)> on_metric;

  const std::string& output_dir() const { return spec.output_dir(); }
  bool cancelled() const { return cancel && cancel->load() != 0; }
  // The committed directories of an input stage (empty when the stage is not an input).
  std::vector<std::string> InputDirs(const std::string& stage) const;
  // The reduce directory of an input stage, or "".
  std::string InputResult(const std::string& stage) const;
};

// What a stage kind's planner reads and sets while the coordinator plans a pipeline (the
// coordinator's StageSpec holds these fields): the kind validates its params and inputs and says
// how many tasks the stage has. Errors are appended, each prefixed by the stage's YAML path.
struct StagePlan {
  const nlohmann::json& params;
  const std::vector<std::string>& inputs;
  int shards = 1;              // map tasks
  bool shards_set = false;     // `shards:` given in the YAML (the kind may pick its default)
  bool reduce = false;         // plus one reduce task
  int world_size = 1;          // gang size
  double timeout_seconds = 0;  // lease of one attempt
  bool timeout_set = false;    // `timeout:` given in the YAML (stage or defaults)
};
using StagePlanner =
    std::function<void(StagePlan& plan, const std::string& path, std::vector<std::string>* errors)>;

// Planning helpers: an integer param in [min, 1e8] (else an error and `fallback`); an error for
// each of `keys` present in the params that names neither one of the stage's inputs nor a path
// pattern (it has a '/').
int IntParam(const nlohmann::json& params, const char* key, int fallback, int min,
             const std::string& path, std::vector<std::string>* errors);
void CheckInputParams(const StagePlan& plan, const std::string& path,
                      std::initializer_list<const char*> keys, std::vector<std::string>* errors);
// The same for keys that may also hold a non-empty list of such names.
void CheckInputListParams(const StagePlan& plan, const std::string& path,
                          std::initializer_list<const char*> keys,
                          std::vector<std::string>* errors);
// Long-running kinds (training, sampling) get a 6 h lease unless the YAML sets one.
inline void LongLease(StagePlan& plan) {
  if (!plan.timeout_set) plan.timeout_seconds = 6 * 3600;
}

// A stage kind is one unit: its executor plans the stage's tasks (in the coordinator) and runs them
// (in the worker), so a new kind is one class registered once.
class StageExecutor {
 public:
  virtual ~StageExecutor() = default;
  virtual std::string Description() const = 0;
  // Plans the stage: validates params and inputs, sets shards/reduce. The default (also for plugin
  // kinds): `shards:` tasks, 1 unless given, and `reduce:` as given.
  virtual void Plan(StagePlan& plan, const std::string& path,
                    std::vector<std::string>* errors) const {
    (void)plan, (void)path, (void)errors;
  }
  // Runs one task. Exceptions are caught by the caller and become task errors.
  virtual TaskReport Run(TaskContext& ctx) = 0;
};

class ExecutorRegistry {
 public:
  void Register(const std::string& kind, std::unique_ptr<StageExecutor> executor);
  StageExecutor* Find(const std::string& kind) const;
  std::vector<std::string> Kinds() const;

 private:
  std::map<std::string, std::unique_ptr<StageExecutor>> executors_;
};

class PluginHost;

// Runs `executor` on the task with its thread budget, catching exceptions.
TaskReport RunTask(StageExecutor& executor, TaskContext& ctx);

// Every regular file under `dir` with its path relative to dir, sha256 and size.
std::vector<wire::OutputFile> ScanOutputs(const std::string& dir);

// The TaskSpec as the JSON handed to plugins (see plugins/api/motionpipe_plugin.h).
std::string TaskSpecToJson(const wire::TaskSpec& spec);

// The built-in stage kinds live in stages/ (one file per kind), outside the engine. Each file
// registers its kind at static initialisation (MP_STAGE_KIND, stages/stage.h); binaries link
// stages/ whole (CMake: motionpipe_stages, linked by the coordinator), so adding a kind is adding
// its file.
using ExecutorFactory = std::unique_ptr<StageExecutor> (*)(const PluginHost* plugins);
bool AddBuiltinKind(const char* kind, ExecutorFactory make);
// A kind the engine plans but a plugin runs (train: its executor is the train plugin, which links
// LibTorch; the C ABI has no planning entry).
bool AddBuiltinPlanner(const char* kind, StagePlanner planner);

// Every built-in kind's executor. `plugins` gives the stages that use labelers and generators
// access to the plugins' (may be null: planning only).
void RegisterBuiltinExecutors(ExecutorRegistry* registry, const PluginHost* plugins = nullptr);
// The planner-only kinds (AddBuiltinPlanner), by kind.
const std::map<std::string, StagePlanner>& BuiltinPlanners();

}  // namespace motionpipe::worker
