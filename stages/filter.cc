// `filter`: SimMotionEdit's dataset filter (sec. 3.2.1), sharded over triplet files.
#include "motionpipe/similarity/filter.h"

#include "stage.h"

namespace motionpipe::stages {

namespace {

// SimMotionEdit's dataset filter (similarity curves, MotionSNR, classes): shard tasks each filter
// their part of the triplet files; the reduce task writes the summary and its plot.
class FilterStage : public StageExecutor {
 public:
  // `shards` tasks (default 8) over the triplet files of the input stage or of params.triplets,
  // then a summary. The similarity constants are checked here, before anything runs.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    if (!plan.shards_set) plan.shards = 8;
    plan.reduce = true;
    const auto& p = plan.params;
    if (p.contains("triplets") && !p["triplets"].is_string() && !p["triplets"].is_array()) {
      errors->push_back(path + ".params.triplets: must be a path or a list of paths");
    }
    if (!p.contains("triplets") && plan.inputs.empty()) {
      errors->push_back(
          path +
          ": needs an input stage (inputs: [corpus]) or params.triplets (files or directories)");
    }
    if (p.contains("input") && (!p["input"].is_string() ||
                                std::find(plan.inputs.begin(), plan.inputs.end(),
                                          p["input"].get<std::string>()) == plan.inputs.end())) {
      errors->push_back(path + ".params.input: must name one of the stage's inputs");
    }
    auto options = similarity::OptionsFromJson(p, path + ".params", {"triplets", "input"});
    if (!options.ok()) errors->push_back(options.status().message());
  }
  std::string Description() const override {
    return "similarity curves, MotionSNR and classes of editing triplets";
  }
  TaskReport Run(TaskContext& ctx) override {
    const auto& p = ctx.params;
    auto options = similarity::OptionsFromJson(p, "params", {"triplets", "input"});
    if (!options.ok()) return TaskReport::BadInput(options.status().message());
    if (ctx.spec.reduce()) {
      const std::vector<std::string> shards(ctx.spec.shard_dirs().begin(),
                                            ctx.spec.shard_dirs().end());
      auto summary = similarity::SummarizeFilter(shards, ctx.output_dir());
      if (!summary.ok()) return TaskReport::FromStatus(summary.status());
      TaskReport report;
      report.metrics["triplets"] = (*summary)["triplets"].get<double>();
      report.metrics["kept"] = (*summary)["kept"].get<double>();
      report.message = similarity::FormatFilterSummary(*summary);
      return report;
    }
    std::vector<std::string> inputs;
    if (p.contains("triplets")) {
      if (p["triplets"].is_string())
        inputs.push_back(p["triplets"].get<std::string>());
      else
        for (const auto& v : p["triplets"]) inputs.push_back(v.get<std::string>());
    } else {
      const std::string stage =
          p.value("input", ctx.spec.inputs_size() > 0 ? ctx.spec.inputs(0).stage() : std::string());
      std::string dir = ctx.InputResult(stage);
      if (dir.empty()) {
        const auto dirs = ctx.InputDirs(stage);
        inputs.insert(inputs.end(), dirs.begin(), dirs.end());
      } else {
        inputs.push_back(dir);
      }
      if (inputs.empty()) return TaskReport::BadInput("input stage '" + stage + "' has no outputs");
    }
    auto files = similarity::ResolveTripletFiles(inputs);
    if (!files.ok()) return TaskReport::FromStatus(files.status());
    const auto slices = similarity::PlanShard(*files, ctx.spec.count(), ctx.spec.index());
    auto report = similarity::FilterShard(slices, *options, ctx.threads, ctx.output_dir());
    if (!report.ok()) return TaskReport::FromStatus(report.status());
    TaskReport out;
    out.metrics["triplets"] = static_cast<double>(report->triplets);
    out.metrics["kept"] = static_cast<double>(report->kept);
    out.metrics["triplets_per_second"] =
        static_cast<double>(report->triplets) / std::max(report->seconds, 1e-9);
    return out;
  }
};

}  // namespace

MP_STAGE_KIND("filter", FilterStage);

}  // namespace motionpipe::stages
