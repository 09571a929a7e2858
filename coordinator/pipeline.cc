#include "pipeline.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>
#include <regex>
#include <set>

#include "cron.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/yaml.h"

namespace motionpipe::coordinator {

namespace {

using Json = nlohmann::ordered_json;
namespace fs = std::filesystem;

std::string PathJoin(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

// Applies "a.b.c=value" (value parsed as YAML) to the document.
Status ApplyOverride(Json* doc, const std::string& override_text) {
  const size_t eq = override_text.find('=');
  if (eq == std::string::npos || eq == 0) {
    return InvalidArgument("override '" + override_text + "': expected key.sub=value");
  }
  const std::string key = override_text.substr(0, eq);
  auto parsed = ParseYaml(override_text.substr(eq + 1), "override '" + override_text + "'");
  if (!parsed.ok()) return parsed.status();
  Json value = std::move(*parsed);
  Json* node = doc;
  size_t start = 0;
  while (true) {
    const size_t dot = key.find('.', start);
    const std::string part =
        key.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    if (part.empty())
      return InvalidArgument("override '" + override_text + "': empty key component");
    if (!node->is_object()) {
      if (!node->is_null())
        return InvalidArgument("override '" + override_text + "': '" + key.substr(0, start - 1) +
                               "' is not a map");
      *node = Json::object();
    }
    if (dot == std::string::npos) {
      (*node)[part] = value;
      return Status::Ok();
    }
    node = &(*node)[part];
    start = dot + 1;
  }
}

const Json* Lookup(const Json& doc, const std::string& dotted) {
  const Json* node = &doc;
  size_t start = 0;
  while (start <= dotted.size()) {
    const size_t dot = dotted.find('.', start);
    const std::string part =
        dotted.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    if (!node->is_object() || !node->contains(part)) return nullptr;
    node = &(*node)[part];
    if (dot == std::string::npos) return node;
    start = dot + 1;
  }
  return nullptr;
}

// ${a.b} references: a whole-string reference keeps the referenced value's type.
void Interpolate(Json* node, const Json& doc, const std::string& path,
                 std::vector<std::string>* errors, int depth = 0) {
  if (depth > 64) return;
  if (node->is_object()) {
    for (auto& [key, value] : node->items())
      Interpolate(&value, doc, PathJoin(path, key), errors, depth + 1);
  } else if (node->is_array()) {
    for (size_t k = 0; k < node->size(); ++k)
      Interpolate(&(*node)[k], doc, path + "[" + std::to_string(k) + "]", errors, depth + 1);
  } else if (node->is_string()) {
    std::string text = node->get<std::string>();
    static const std::regex kRef("\\$\\{([A-Za-z0-9_.-]+)\\}");
    std::smatch match;
    if (std::regex_match(text, match, kRef)) {
      const Json* value = Lookup(doc, match[1]);
      if (!value) {
        errors->push_back(path + ": unknown reference ${" + match[1].str() + "}");
      } else {
        *node = *value;
      }
      return;
    }
    std::string out;
    auto begin = text.cbegin();
    while (std::regex_search(begin, text.cend(), match, kRef)) {
      out.append(begin, match[0].first);
      const Json* value = Lookup(doc, match[1]);
      if (!value) {
        errors->push_back(path + ": unknown reference ${" + match[1].str() + "}");
      } else {
        out += value->is_string() ? value->get<std::string>() : value->dump();
      }
      begin = match[0].second;
    }
    out.append(begin, text.cend());
    *node = out;
  }
}

bool ValidName(const std::string& name) {
  static const std::regex kName("[A-Za-z0-9_][A-Za-z0-9_.-]*");
  return std::regex_match(name, kName);
}

void CheckKeys(const Json& map, const std::set<std::string>& allowed, const std::string& path,
               std::vector<std::string>* errors) {
  for (const auto& [key, value] : map.items()) {
    if (!allowed.count(key)) errors->push_back(PathJoin(path, key) + ": unknown key");
  }
}

bool ReadInt(const Json& node, const std::string& path, int min, int* out,
             std::vector<std::string>* errors) {
  if (!node.is_number_integer() || node.get<int64_t>() < min ||
      node.get<int64_t>() > 1'000'000'000) {
    errors->push_back(path + ": must be an integer >= " + std::to_string(min));
    return false;
  }
  *out = static_cast<int>(node.get<int64_t>());
  return true;
}

bool ReadDuration(const Json& node, const std::string& path, double* out,
                  std::vector<std::string>* errors) {
  if (node.is_number() && node.get<double>() >= 0) {
    *out = node.get<double>();
    return true;
  }
  if (node.is_string() && ParseDuration(node.get<std::string>(), out)) return true;
  errors->push_back(path + ": must be a duration such as 30s, 15m or 2h");
  return false;
}

void ReadStageSettings(const Json& map, const std::string& path, StageSpec* stage,
                       std::vector<std::string>* errors) {
  if (map.contains("max_attempts"))
    ReadInt(map["max_attempts"], PathJoin(path, "max_attempts"), 1, &stage->max_attempts, errors);
  if (map.contains("retry_backoff"))
    ReadDuration(map["retry_backoff"], PathJoin(path, "retry_backoff"),
                 &stage->retry_backoff_seconds, errors);
  if (map.contains("timeout")) {
    stage->timeout_set =
        ReadDuration(map["timeout"], PathJoin(path, "timeout"), &stage->timeout_seconds, errors);
  }
  if (map.contains("poison_threshold"))
    ReadInt(map["poison_threshold"], PathJoin(path, "poison_threshold"), 1,
            &stage->poison_threshold, errors);
  if (map.contains("threads"))
    ReadInt(map["threads"], PathJoin(path, "threads"), 0, &stage->threads, errors);
}

// A stage node's input names (a list or one name; what is not a name is ReadInputs' to report).
std::vector<std::string> InputNames(const Json& node) {
  std::vector<std::string> inputs;
  if (node.contains("inputs") && node["inputs"].is_array()) {
    for (const Json& i : node["inputs"]) {
      if (i.is_string()) inputs.push_back(i.get<std::string>());
    }
  } else if (node.contains("inputs") && node["inputs"].is_string()) {
    inputs.push_back(node["inputs"].get<std::string>());
  }
  return inputs;
}

// `targets: [stage, ...]` keeps those stages and every stage they need through their inputs, and
// drops the rest: a part of a pipeline (one claim's rows of a claims config) without a copy of it.
void SelectTargets(Json* doc, std::vector<std::string>* errors) {
  if (!doc->contains("targets")) return;
  const Json& targets = (*doc)["targets"];
  if (!targets.is_array() || targets.empty()) {
    errors->push_back("targets: must be a non-empty list of stage names");
    return;
  }
  if (!doc->contains("stages") || !(*doc)["stages"].is_object()) return;  // reported later
  Json& stages = (*doc)["stages"];
  std::set<std::string> keep;
  std::vector<std::string> pending;
  for (size_t k = 0; k < targets.size(); ++k) {
    if (!targets[k].is_string() || !stages.contains(targets[k].get<std::string>())) {
      errors->push_back("targets[" + std::to_string(k) + "]: not a stage of this pipeline (" +
                        targets[k].dump() + ")");
      continue;
    }
    pending.push_back(targets[k].get<std::string>());
  }
  while (!pending.empty()) {
    const std::string name = pending.back();
    pending.pop_back();
    if (!keep.insert(name).second) continue;
    // An input that is not a stage is left for CheckInputs to report, with its path.
    for (const std::string& input : InputNames(stages[name]))
      if (stages.contains(input)) pending.push_back(input);
  }
  if (keep.empty()) return;
  Json kept = Json::object();
  for (const auto& [name, node] : stages.items())
    if (keep.count(name)) kept[name] = node;
  stages = std::move(kept);
}

// `seeds: N` on a stage replicates it N times: `name`, `name-s2`, ..., `name-sN`, replicate k with
// params.seed = (params.seed or the pipeline's seed) + k - 1. A seeded stage whose input is seeded
// too takes the input's replicate k (both must have the same N), and top-level string params naming
// that input follow it (model: mdt -> model: mdt-s2). An unseeded stage with a seeded input waits
// for every replicate; its params keep naming replicate 1.
void ExpandSeeds(Json* stages, uint64_t pipeline_seed, std::vector<std::string>* errors) {
  std::map<std::string, int> seeds;
  for (const auto& [name, node] : stages->items()) {
    if (!node.is_object() || !node.contains("seeds")) continue;
    const Json& n = node["seeds"];
    if (!n.is_number_integer() || n.get<int64_t>() < 1 || n.get<int64_t>() > 100) {
      errors->push_back("stages." + name + ".seeds: must be an integer from 1 to 100");
      continue;
    }
    seeds[name] = static_cast<int>(n.get<int64_t>());
  }
  if (seeds.empty()) return;
  const auto replicate = [](const std::string& name, int k) {
    return k == 1 ? name : name + "-s" + std::to_string(k);
  };
  Json out = Json::object();
  for (const auto& [name, node] : stages->items()) {
    if (!node.is_object()) {
      out[name] = node;
      continue;
    }
    const std::vector<std::string> inputs = InputNames(node);
    const auto own = seeds.find(name);
    if (own == seeds.end()) {  // unseeded: waits for every replicate of its seeded inputs
      Json copy = node;
      if (node.contains("inputs") && (node["inputs"].is_array() || node["inputs"].is_string())) {
        Json all = Json::array();
        for (const std::string& input : inputs) {
          const auto s = seeds.find(input);
          for (int k = 1; k <= (s == seeds.end() ? 1 : s->second); ++k)
            all.push_back(replicate(input, k));
        }
        copy["inputs"] = all;
      }
      out[name] = copy;
      continue;
    }
    const int n = own->second;
    // Replicate k's seed is computed from this one, so it must be a number: a quoted "6" would
    // leave replicate 1 with the text and give the others the pipeline's seeds.
    if (node.contains("params") && node["params"].is_object() && node["params"].contains("seed") &&
        !(node["params"]["seed"].is_number_integer() &&
          node["params"]["seed"].get<int64_t>() >= 0)) {
      errors->push_back("stages." + name + ".params.seed: must be a non-negative integer (got " +
                        node["params"]["seed"].dump() + "); replicate k trains with seed + k - 1");
      continue;
    }
    for (const std::string& input : inputs) {
      const auto s = seeds.find(input);
      if (s != seeds.end() && s->second != n) {
        errors->push_back("stages." + name + ".seeds: " + std::to_string(n) +
                          " replicates, but its input '" + input + "' has " +
                          std::to_string(s->second) + " (seeded chains need the same count)");
      }
    }
    for (int k = 1; k <= n; ++k) {
      Json copy = node;
      copy.erase("seeds");
      if (!inputs.empty()) {
        Json renamed = Json::array();
        for (const std::string& input : inputs)
          renamed.push_back(seeds.count(input) ? replicate(input, k) : input);
        copy["inputs"] = renamed;
      }
      if (!copy.contains("params") || !copy["params"].is_object()) copy["params"] = Json::object();
      Json& params = copy["params"];
      for (auto& [key, value] : params.items()) {
        if (value.is_string() && seeds.count(value.get<std::string>()) &&
            std::find(inputs.begin(), inputs.end(), value.get<std::string>()) != inputs.end()) {
          value = replicate(value.get<std::string>(), k);
        }
      }
      if (k > 1) {
        const uint64_t base =
            params.contains("seed") ? params["seed"].get<uint64_t>() : pipeline_seed;
        params["seed"] = base + static_cast<uint64_t>(k - 1);
      }
      copy["replicate"] = k;
      out[replicate(name, k)] = copy;
    }
  }
  *stages = std::move(out);
}

}  // namespace

bool ParseDuration(const std::string& text, double* seconds) {
  static const std::regex kDuration("\\s*([0-9]*\\.?[0-9]+)\\s*(ms|s|m|h|d)?\\s*");
  std::smatch match;
  if (!std::regex_match(text, match, kDuration)) return false;
  const double value = std::stod(match[1]);
  const std::string unit = match[2];
  const double scale = unit == "ms"  ? 1e-3
                       : unit == "m" ? 60
                       : unit == "h" ? 3600
                       : unit == "d" ? 86400
                                     : 1;
  *seconds = value * scale;
  return true;
}

KindRegistry KindRegistry::FromExecutors(
    std::shared_ptr<const worker::ExecutorRegistry> executors) {
  KindRegistry registry;
  for (const std::string& kind : executors->Kinds()) {
    const worker::StageExecutor* executor = executors->Find(kind);
    registry.Add(kind, [executors, executor](worker::StagePlan& plan, const std::string& path,
                                             std::vector<std::string>* errors) {
      executor->Plan(plan, path, errors);
    });
  }
  return registry;
}

KindRegistry KindRegistry::WithBuiltins() {
  auto executors = std::make_shared<worker::ExecutorRegistry>();
  worker::RegisterBuiltinExecutors(executors.get());
  KindRegistry registry = FromExecutors(executors);
  for (const auto& [kind, planner] : worker::BuiltinPlanners()) registry.Add(kind, planner);
  return registry;
}

void KindRegistry::Add(const std::string& kind, StagePlanner planner) {
  planners_[kind] = std::move(planner);
}

void KindRegistry::AddGeneric(const std::string& kind) {
  if (planners_.count(kind)) return;
  planners_[kind] = [](worker::StagePlan&, const std::string&, std::vector<std::string>*) {};
}

const StagePlanner* KindRegistry::Find(const std::string& kind) const {
  const auto it = planners_.find(kind);
  return it == planners_.end() ? nullptr : &it->second;
}

std::vector<std::string> KindRegistry::Kinds() const {
  std::vector<std::string> out;
  for (const auto& [kind, planner] : planners_) out.push_back(kind);
  return out;
}

namespace {

// `scale: NAME` picks `scales.NAME`, a map of vars: they override the file's vars, and
// command-line overrides (which may also pick the scale) override both.
Status ApplyScale(Json* doc, const std::vector<std::string>& overrides, const std::string& origin,
                  std::vector<std::string>* errors) {
  if (!doc->contains("scale") && !doc->contains("scales")) return Status::Ok();
  Json chosen = *doc;
  for (const std::string& o : overrides)
    MP_RETURN_IF_ERROR(ApplyOverride(&chosen, o).WithContext(origin));
  const Json scale = chosen.value("scale", Json());
  const Json scales = chosen.value("scales", Json::object());
  if (!scale.is_string() || !scales.is_object() || !scales.contains(scale.get<std::string>()) ||
      !scales[scale.get<std::string>()].is_object()) {
    std::string known;
    if (scales.is_object()) {
      for (const auto& [name, value] : scales.items()) known += (known.empty() ? "" : ", ") + name;
    }
    errors->push_back("scale: must name one of scales (" +
                      (known.empty() ? std::string("none defined") : known) + "), got " +
                      scale.dump());
    return Status::Ok();
  }
  if (!doc->contains("vars") || !(*doc)["vars"].is_object()) (*doc)["vars"] = Json::object();
  for (const auto& [key, value] : scales[scale.get<std::string>()].items())
    (*doc)["vars"][key] = value;
  (*doc)["vars"]["scale"] = scale;
  return Status::Ok();
}

// The pipeline's own fields: name, output_root, seed, schedule.
void ReadHeader(const Json& doc, PipelineSpec* spec, std::vector<std::string>* errors) {
  if (!doc.contains("name") || !doc["name"].is_string() ||
      !ValidName(doc["name"].get<std::string>())) {
    errors->push_back("name: required; letters, digits, '_', '.', '-'");
  } else {
    spec->name = doc["name"].get<std::string>();
  }
  if (doc.contains("output_root")) {
    if (doc["output_root"].is_string() && !doc["output_root"].get<std::string>().empty()) {
      spec->output_root = doc["output_root"].get<std::string>();
    } else {
      errors->push_back("output_root: must be a non-empty string");
    }
  }
  if (doc.contains("seed")) {
    if (doc["seed"].is_number_integer() && doc["seed"].get<int64_t>() >= 0) {
      spec->seed = doc["seed"].get<uint64_t>();
    } else {
      errors->push_back("seed: must be a non-negative integer");
    }
  }
  if (doc.contains("schedule") && !doc["schedule"].is_null()) {
    if (!doc["schedule"].is_string()) {
      errors->push_back("schedule: must be a cron string such as \"0 3 * * *\"");
    } else {
      // An empty schedule (the override `schedule=`, or `schedule=""`) runs a recurring pipeline
      // once, now.
      spec->schedule = doc["schedule"].get<std::string>();
      if (!spec->schedule.empty()) {
        auto cron = ParseCron(spec->schedule);
        if (!cron.ok()) errors->push_back("schedule: " + cron.status().message());
      }
    }
  }
}

// `defaults:`, the settings every stage starts from.
StageSpec ReadDefaults(const Json& doc, std::vector<std::string>* errors) {
  StageSpec defaults;
  if (!doc.contains("defaults")) return defaults;
  if (!doc["defaults"].is_object()) {
    errors->push_back("defaults: must be a map");
    return defaults;
  }
  CheckKeys(doc["defaults"],
            {"max_attempts", "retry_backoff", "timeout", "poison_threshold", "threads"}, "defaults",
            errors);
  ReadStageSettings(doc["defaults"], "defaults", &defaults, errors);
  return defaults;
}

void ReadInputs(const Json& node, const std::string& path, StageSpec* stage,
                std::vector<std::string>* errors) {
  if (!node.contains("inputs")) return;
  const Json& inputs = node["inputs"];
  if (inputs.is_string()) {
    stage->inputs.push_back(inputs.get<std::string>());
  } else if (inputs.is_array()) {
    for (size_t k = 0; k < inputs.size(); ++k) {
      if (!inputs[k].is_string()) {
        errors->push_back(path + ".inputs[" + std::to_string(k) + "]: must be a stage name");
      } else {
        stage->inputs.push_back(inputs[k].get<std::string>());
      }
    }
  } else {
    errors->push_back(path + ".inputs: must be a list of stage names");
  }
}

// The kind's planner checks the params and sets the task count.
void PlanStage(const KindRegistry& kinds, const std::string& path, StageSpec* stage,
               std::vector<std::string>* errors) {
  if (stage->kind.empty()) return;
  const StagePlanner* planner = kinds.Find(stage->kind);
  if (!planner) {
    std::string known;
    for (const std::string& k : kinds.Kinds()) known += (known.empty() ? "" : ", ") + k;
    errors->push_back(path + ".kind: unknown kind '" + stage->kind + "' (known: " + known +
                      "; plugins add more)");
    return;
  }
  worker::StagePlan plan{stage->params,          stage->inputs,     stage->shards,
                         stage->shards_set,      stage->reduce,     stage->world_size,
                         stage->timeout_seconds, stage->timeout_set};
  (*planner)(plan, path, errors);
  stage->shards = plan.shards;
  stage->reduce = plan.reduce;
  stage->timeout_seconds = plan.timeout_seconds;
  if (stage->world_size > 1) {  // a gang: one task per rank, no reduce
    stage->shards = stage->world_size;
    stage->reduce = false;
  }
}

// One entry of `stages:`; nothing when it is not a map.
std::optional<StageSpec> ReadStage(const std::string& name, const Json& node,
                                   const StageSpec& defaults, const KindRegistry& kinds,
                                   std::vector<std::string>* errors) {
  const std::string path = "stages." + name;
  StageSpec stage = defaults;
  stage.name = name;
  if (!ValidName(name))
    errors->push_back(path + ": stage names use letters, digits, '_', '.', '-'");
  if (!node.is_object()) {
    errors->push_back(path + ": must be a map with at least 'kind'");
    return std::nullopt;
  }
  CheckKeys(node,
            {"kind", "inputs", "params", "shards", "reduce", "max_attempts", "retry_backoff",
             "timeout", "poison_threshold", "threads", "world_size", "description", "replicate"},
            path, errors);
  if (!node.contains("kind") || !node["kind"].is_string()) {
    errors->push_back(path + ".kind: required");
  } else {
    stage.kind = node["kind"].get<std::string>();
  }
  ReadInputs(node, path, &stage, errors);
  if (node.contains("params")) {
    if (!node["params"].is_object() && !node["params"].is_null()) {
      errors->push_back(path + ".params: must be a map");
    } else if (node["params"].is_object()) {
      stage.params = nlohmann::json::parse(node["params"].dump());
    }
  }
  if (node.contains("shards"))
    stage.shards_set = ReadInt(node["shards"], path + ".shards", 1, &stage.shards, errors);
  if (node.contains("reduce")) {
    if (!node["reduce"].is_boolean())
      errors->push_back(path + ".reduce: must be true or false");
    else
      stage.reduce = node["reduce"].get<bool>();
  }
  if (node.contains("world_size"))
    ReadInt(node["world_size"], path + ".world_size", 1, &stage.world_size, errors);
  ReadStageSettings(node, path, &stage, errors);
  if (node.contains("replicate") && node["replicate"].is_number_integer())
    stage.replicate = node["replicate"].get<int>();
  PlanStage(kinds, path, &stage, errors);
  return stage;
}

// Inputs must name other stages.
void CheckInputs(const std::vector<StageSpec>& stages, std::vector<std::string>* errors) {
  std::set<std::string> names;
  for (const StageSpec& stage : stages) names.insert(stage.name);
  for (const StageSpec& stage : stages) {
    for (size_t k = 0; k < stage.inputs.size(); ++k) {
      const std::string& input = stage.inputs[k];
      if (input == stage.name)
        errors->push_back("stages." + stage.name + ".inputs[" + std::to_string(k) +
                          "]: a stage cannot be its own input");
      else if (!names.count(input))
        errors->push_back("stages." + stage.name + ".inputs[" + std::to_string(k) +
                          "]: unknown stage '" + input + "'");
    }
  }
}

// The stages in an order where each comes after its inputs (Kahn's algorithm, stable in file
// order); an error naming the stages of a cycle.
std::vector<StageSpec> TopologicalOrder(const std::vector<StageSpec>& stages,
                                        std::vector<std::string>* errors) {
  std::vector<StageSpec> ordered;
  std::vector<int> pending(stages.size(), 0);
  for (size_t s = 0; s < stages.size(); ++s) pending[s] = static_cast<int>(stages[s].inputs.size());
  std::vector<bool> done(stages.size(), false);
  bool progress = true;
  while (progress) {
    progress = false;
    for (size_t s = 0; s < stages.size(); ++s) {
      if (done[s] || pending[s] > 0) continue;
      done[s] = true;
      progress = true;
      ordered.push_back(stages[s]);
      for (size_t t = 0; t < stages.size(); ++t) {
        for (const std::string& input : stages[t].inputs) pending[t] -= input == stages[s].name;
      }
    }
  }
  if (ordered.size() != stages.size()) {
    std::string cycle;
    for (size_t s = 0; s < stages.size(); ++s) {
      if (!done[s]) cycle += (cycle.empty() ? "" : ", ") + stages[s].name;
    }
    errors->push_back("stages: the inputs form a cycle among " + cycle);
  }
  return ordered;
}

// A job's tasks live in the coordinator's memory and journal: `shards: 1000000000` (or clips
// counted in billions) must be an error here, not an allocation that kills the coordinator.
void CheckTaskCount(const std::vector<StageSpec>& stages, std::vector<std::string>* errors) {
  int64_t tasks = 0;
  std::string largest;
  int64_t largest_tasks = -1;
  for (const StageSpec& stage : stages) {
    const int64_t n = static_cast<int64_t>(stage.shards) + (stage.reduce ? 1 : 0);
    tasks += n;
    if (n > largest_tasks) largest_tasks = n, largest = stage.name;
  }
  if (tasks > kMaxJobTasks) {
    errors->push_back("the pipeline plans " + std::to_string(tasks) + " tasks (stage " + largest +
                      ": " + std::to_string(largest_tasks) + "); a job holds at most " +
                      std::to_string(kMaxJobTasks));
  }
}

// `doc`, read from `path`, with its bases merged under it; `chain` holds the files that derive
// from it, to name a cycle.
Result<Json> MergeBases(Json doc, const std::string& path, std::vector<std::string>* chain) {
  if (!doc.is_object() || !doc.contains("base")) return doc;
  const Json& base = doc["base"];
  if (!base.is_string() || base.get<std::string>().empty())
    return InvalidArgument(path + ": base: must be the path of a pipeline file, relative to " +
                           "this one (got " + base.dump() + ")");
  if (!doc.contains("name"))
    return InvalidArgument(path + ": name: required in a derived pipeline (its outputs would " +
                           "go under its base's name)");
  const std::string base_path =
      (fs::path(path).parent_path() / base.get<std::string>()).lexically_normal().string();
  chain->push_back(fs::path(path).lexically_normal().string());
  if (std::find(chain->begin(), chain->end(), base_path) != chain->end()) {
    std::string cycle;
    for (const std::string& file : *chain) cycle += file + " -> ";
    return InvalidArgument(path + ": base: a cycle: " + cycle + base_path);
  }
  auto text = ReadFile(base_path);
  if (!text.ok()) return text.status().WithContext(path + ": base");
  auto parsed = ParseYaml(*text, base_path);
  if (!parsed.ok()) return parsed.status().WithContext(path + ": base");
  if (!parsed->is_object())
    return InvalidArgument(path + ": base: " + base_path + " is not a pipeline (a YAML map)");
  MP_ASSIGN_OR_RETURN(Json merged, MergeBases(std::move(*parsed), base_path, chain));
  doc.erase("base");
  merged.merge_patch(doc);
  return merged;
}

}  // namespace

Result<std::string> ReadPipelineFile(const std::string& path) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  auto doc = ParseYaml(*text, path);
  // Without a base (or unparsable: ParsePipeline reports it), the file's own text.
  if (!doc.ok() || !doc->is_object() || !doc->contains("base")) return text;
  std::vector<std::string> chain;
  MP_ASSIGN_OR_RETURN(Json merged, MergeBases(std::move(*doc), path, &chain));
  return merged.dump(2);
}

// Every problem of the file is collected (each with its YAML path) and reported together.
Result<PipelineSpec> ParsePipeline(const std::string& yaml_text,
                                   const std::vector<std::string>& overrides,
                                   const std::string& origin, const KindRegistry& kinds) {
  auto parsed = ParseYaml(yaml_text, origin);
  if (!parsed.ok()) return parsed.status();
  Json doc = std::move(*parsed);
  if (!doc.is_object())
    return InvalidArgument(origin + ": a pipeline is a YAML map with 'name' and 'stages'");
  std::vector<std::string> errors;
  MP_RETURN_IF_ERROR(ApplyScale(&doc, overrides, origin, &errors));
  for (const std::string& o : overrides)
    MP_RETURN_IF_ERROR(ApplyOverride(&doc, o).WithContext(origin));
  Interpolate(&doc, Json(doc), "", &errors);
  if (doc.contains("base")) {
    errors.push_back(
        "base: a derived pipeline is resolved when its file is read (motionpipe run / submit, "
        "ReadPipelineFile), not in pipeline text");
    doc.erase("base");
  }
  CheckKeys(doc,
            {"name", "description", "output_root", "seed", "schedule", "scale", "scales", "vars",
             "defaults", "targets", "stages"},
            "", &errors);
  SelectTargets(&doc, &errors);

  PipelineSpec spec;
  ReadHeader(doc, &spec, &errors);
  const StageSpec defaults = ReadDefaults(doc, &errors);
  if (doc.contains("stages") && doc["stages"].is_object())
    ExpandSeeds(&doc["stages"], spec.seed, &errors);
  if (!doc.contains("stages") || !doc["stages"].is_object() || doc["stages"].empty()) {
    errors.push_back("stages: required, a map of stage name -> stage");
  } else {
    for (const auto& [name, node] : doc["stages"].items()) {
      std::optional<StageSpec> stage = ReadStage(name, node, defaults, kinds, &errors);
      if (stage) spec.stages.push_back(std::move(*stage));
    }
  }
  CheckInputs(spec.stages, &errors);
  std::vector<StageSpec> ordered;
  if (errors.empty()) ordered = TopologicalOrder(spec.stages, &errors);
  CheckTaskCount(spec.stages, &errors);
  if (!errors.empty()) {
    std::string message = origin + ": invalid pipeline:";
    for (const std::string& e : errors) message += "\n  " + origin + ": " + e;
    return InvalidArgument(message);
  }
  spec.stages = std::move(ordered);
  spec.resolved = doc.dump();
  spec.fingerprint = Sha256Hex(spec.resolved);
  return spec;
}

}  // namespace motionpipe::coordinator
