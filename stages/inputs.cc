#include "inputs.h"

#include <glob.h>

#include <filesystem>

#include "motionpipe/base/job_layout.h"
#include "motionpipe/sinc/texts.h"

namespace motionpipe::stages {

namespace fs = std::filesystem;

std::vector<std::string> StringList(const json& v) {
  std::vector<std::string> out;
  if (v.is_string()) out.push_back(v.get<std::string>());
  if (v.is_array()) {
    for (const auto& item : v) out.push_back(item.get<std::string>());
  }
  return out;
}

std::vector<std::string> StageDirs(const TaskContext& ctx, const std::string& stage) {
  std::vector<std::string> dirs;
  if (stage.find('/') == std::string::npos) {
    for (const auto& input : ctx.spec.inputs()) {
      if (!stage.empty() && input.stage() != stage) continue;
      if (!input.result_dir().empty()) dirs.push_back(input.result_dir());
      for (const auto& d : input.dirs()) dirs.push_back(d);
    }
    return dirs;
  }
  glob_t matches{};
  if (::glob(stage.c_str(), 0, nullptr, &matches) == 0) {
    for (size_t k = 0; k < matches.gl_pathc; ++k) {
      const std::vector<std::string> tasks = layout::StageOutputDirs(matches.gl_pathv[k]);
      dirs.insert(dirs.end(), tasks.begin(), tasks.end());
    }
  }
  globfree(&matches);
  return dirs;
}

std::vector<std::string> TripletFiles(const TaskContext& ctx, const std::string& stage) {
  std::vector<std::string> stages = {stage};
  if (stage.empty()) {
    stages.clear();
    for (const auto& input : ctx.spec.inputs()) stages.push_back(input.stage());
  }
  std::vector<std::string> dirs;
  for (const std::string& name : stages) {
    const std::vector<std::string> found = StageDirs(ctx, name);
    dirs.insert(dirs.end(), found.begin(), found.end());
  }
  return StageTripletFiles(dirs);
}

std::string FindCheckpoint(const TaskContext& ctx, const std::string& stage) {
  if (stage.find('/') != std::string::npos) {
    glob_t matches{};
    std::string newest;
    fs::file_time_type newest_time{};
    if (::glob(stage.c_str(), 0, nullptr, &matches) == 0) {
      for (size_t k = 0; k < matches.gl_pathc; ++k) {
        auto resolved = ResolveCheckpoint(matches.gl_pathv[k]);
        if (!resolved.ok()) continue;
        std::error_code ec;
        const auto time = fs::last_write_time(layout::ModelConfigFile(*resolved), ec);
        if (!ec && (newest.empty() || time > newest_time)) newest = *resolved, newest_time = time;
      }
    }
    globfree(&matches);
    return newest;
  }
  for (const auto& input : ctx.spec.inputs()) {
    if (!stage.empty() && input.stage() != stage) continue;
    for (const auto& dir : input.dirs()) {
      if (auto resolved = ResolveCheckpoint(dir); resolved.ok()) return *resolved;
    }
  }
  return "";
}

Result<GeneratorPtr> OpenModel(const TaskContext& ctx, const PluginHost& plugins,
                               const json& options, std::string* checkpoint,
                               const std::string& model) {
  *checkpoint = FindCheckpoint(ctx, ctx.params.value("model", std::string()));
  if (checkpoint->empty()) return NotFound("no input holds a checkpoint (a train stage's model/)");
  if (!model.empty()) {
    MP_ASSIGN_OR_RETURN(const std::string name, worker::CheckpointModelName(*checkpoint));
    if (name != model)
      return InvalidArgument(*checkpoint + " is a " + name + " checkpoint, not a " + model +
                             " one");
  }
  return LoadGenerator(plugins, *checkpoint, options);
}

Result<sinc::SpanTable> InputSpans(const TaskContext& ctx, const std::string& stage) {
  for (const std::string& dir : StageDirs(ctx, stage)) {
    if (fs::exists(dir + "/spans.npz")) return sinc::ReadSpans(dir + "/spans.npz");
  }
  return NotFound("no spans.npz in " + (stage.empty() ? std::string("the inputs") : stage) +
                  " (a `singles` stage)");
}

std::vector<int64_t> SelectSpans(const sinc::SpanTable& table, const json& p) {
  const std::string split = p.value("split", std::string("test")),
                    kind = p.value("spans", std::string("pairs"));
  const int64_t limit = p.value("limit", int64_t{0});
  std::vector<int64_t> out;
  for (int64_t i = 0; i < table.size(); ++i) {
    if (table.splits[static_cast<size_t>(i)] != split) continue;
    if ((kind == "pairs" && table.single(i)) || (kind == "singles" && !table.single(i))) continue;
    out.push_back(i);
    if (limit > 0 && static_cast<int64_t>(out.size()) >= limit) break;
  }
  return out;
}

std::string SpanText(const sinc::SpanTable& table, int64_t i) {
  return table.single(i) ? table.text_a[static_cast<size_t>(i)]
                         : sinc::EvalPairText(table.text_a[static_cast<size_t>(i)],
                                              table.text_b[static_cast<size_t>(i)]);
}

}  // namespace motionpipe::stages
