#include "executor.h"

#include <omp.h>

#include <algorithm>
#include <filesystem>

#include "motionpipe/base/file.h"

namespace motionpipe::worker {

TaskReport TaskReport::FromStatus(const Status& s) {
  switch (s.code()) {
    case StatusCode::kInvalidArgument:
    case StatusCode::kNotFound:
    case StatusCode::kDataLoss:
      return BadInput(s.message());
    default:
      return Error(s.message());
  }
}

int IntParam(const nlohmann::json& params, const char* key, int fallback, int min,
             const std::string& path, std::vector<std::string>* errors) {
  if (!params.contains(key)) return fallback;
  const auto& v = params[key];
  if (!v.is_number_integer() || v.get<int64_t>() < min || v.get<int64_t>() > 100'000'000) {
    errors->push_back(path + ".params." + key + ": must be an integer >= " + std::to_string(min));
    return fallback;
  }
  return static_cast<int>(v.get<int64_t>());
}

namespace {
bool NamesAnInput(const StagePlan& plan, const nlohmann::json& value) {
  return value.is_string() && (value.get<std::string>().find('/') != std::string::npos ||
                               std::find(plan.inputs.begin(), plan.inputs.end(),
                                         value.get<std::string>()) != plan.inputs.end());
}
}  // namespace

void CheckInputParams(const StagePlan& plan, const std::string& path,
                      std::initializer_list<const char*> keys, std::vector<std::string>* errors) {
  for (const char* key : keys) {
    if (plan.params.contains(key) && !NamesAnInput(plan, plan.params[key]))
      errors->push_back(path + ".params." + key +
                        ": must name one of the stage's inputs (or a checkpoint path pattern)");
  }
}

void CheckInputListParams(const StagePlan& plan, const std::string& path,
                          std::initializer_list<const char*> keys,
                          std::vector<std::string>* errors) {
  for (const char* key : keys) {
    if (!plan.params.contains(key)) continue;
    const nlohmann::json& value = plan.params[key];
    bool names = !value.is_array() || !value.empty();
    for (const auto& one : value.is_array() ? value : nlohmann::json::array({value}))
      names = names && NamesAnInput(plan, one);
    if (!names)
      errors->push_back(path + ".params." + key +
                        ": must name one of the stage's inputs (or a checkpoint path pattern), or "
                        "be a non-empty list of them");
  }
}

std::vector<std::string> TaskContext::InputDirs(const std::string& stage) const {
  for (const auto& input : spec.inputs()) {
    if (input.stage() == stage) return {input.dirs().begin(), input.dirs().end()};
  }
  return {};
}

std::string TaskContext::InputResult(const std::string& stage) const {
  for (const auto& input : spec.inputs()) {
    if (input.stage() == stage) return input.result_dir();
  }
  return "";
}

void ExecutorRegistry::Register(const std::string& kind, std::unique_ptr<StageExecutor> executor) {
  executors_[kind] = std::move(executor);
}

StageExecutor* ExecutorRegistry::Find(const std::string& kind) const {
  const auto it = executors_.find(kind);
  return it == executors_.end() ? nullptr : it->second.get();
}

namespace {

struct BuiltinKinds {
  std::map<std::string, ExecutorFactory> executors;
  std::map<std::string, StagePlanner> planners;
};

// Filled at static initialisation, before main: a function-local static has no order problem.
BuiltinKinds& Builtins() {
  static BuiltinKinds builtins;
  return builtins;
}

}  // namespace

bool AddBuiltinKind(const char* kind, ExecutorFactory make) {
  return Builtins().executors.emplace(kind, make).second;
}

bool AddBuiltinPlanner(const char* kind, StagePlanner planner) {
  return Builtins().planners.emplace(kind, std::move(planner)).second;
}

void RegisterBuiltinExecutors(ExecutorRegistry* registry, const PluginHost* plugins) {
  for (const auto& [kind, make] : Builtins().executors) registry->Register(kind, make(plugins));
}

const std::map<std::string, StagePlanner>& BuiltinPlanners() { return Builtins().planners; }

std::vector<std::string> ExecutorRegistry::Kinds() const {
  std::vector<std::string> kinds;
  for (const auto& [kind, executor] : executors_) kinds.push_back(kind);
  return kinds;
}

TaskReport RunTask(StageExecutor& executor, TaskContext& ctx) {
  omp_set_num_threads(std::max(1, ctx.threads));
  try {
    return executor.Run(ctx);
  } catch (const std::exception& e) {
    return TaskReport::Error(std::string("exception: ") + e.what());
  } catch (...) {
    return TaskReport::Error("unknown exception");
  }
}

std::vector<wire::OutputFile> ScanOutputs(const std::string& dir) {
  std::vector<wire::OutputFile> outputs;
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec)) return outputs;
  std::vector<std::filesystem::path> files;
  for (auto it = std::filesystem::recursive_directory_iterator(dir, ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
    if (it->is_symlink())
      continue;  // links to the user's data (the dataset stage) are not task outputs
    if (it->is_regular_file()) files.push_back(it->path());
  }
  std::sort(files.begin(), files.end());
  for (const auto& path : files) {
    auto bytes = ReadFile(path.string());
    if (!bytes.ok()) continue;
    wire::OutputFile out;
    out.set_path(std::filesystem::relative(path, dir).string());
    out.set_sha256(Sha256Hex(*bytes));
    out.set_bytes(static_cast<int64_t>(bytes->size()));
    outputs.push_back(std::move(out));
  }
  return outputs;
}

std::string TaskSpecToJson(const wire::TaskSpec& spec) {
  nlohmann::json inputs = nlohmann::json::array();
  for (const auto& input : spec.inputs()) {
    inputs.push_back({{"stage", input.stage()},
                      {"dirs", std::vector<std::string>(input.dirs().begin(), input.dirs().end())},
                      {"result_dir", input.result_dir()}});
  }
  nlohmann::json params = nlohmann::json::object();
  try {
    params = nlohmann::json::parse(spec.params_json().empty() ? "{}" : spec.params_json());
  } catch (...) {
  }
  return nlohmann::json{
      {"job_id", spec.job_id()},
      {"job_name", spec.job_name()},
      {"stage", spec.stage()},
      {"kind", spec.kind()},
      {"index", spec.index()},
      {"count", spec.count()},
      {"reduce", spec.reduce()},
      {"params", params},
      {"output_dir", spec.output_dir()},
      {"inputs", inputs},
      {"shard_dirs", std::vector<std::string>(spec.shard_dirs().begin(), spec.shard_dirs().end())},
      {"seed", spec.seed()},
      {"threads", spec.threads()},
      {"attempt", spec.attempt()},
      {"world_size", std::max(1, spec.world_size())},
      {"rendezvous", spec.rendezvous()},
      {"state_dir", spec.state_dir()}}
      .dump();
}

}  // namespace motionpipe::worker
