// `report`: the job's HTML report once its inputs are done.
#include "report.h"

#include <filesystem>

#include "motionpipe/base/file.h"
#include "motionpipe/base/log.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// The job's HTML report (report.h) once its inputs (the evaluation stages) are done:
// report.html in this task's directory. params: history (an evaluation history to plot), title,
// previews (true), panel_size (200).
class ReportStage : public StageExecutor {
 public:
  // One task after its inputs (the evaluation stages).
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    if (plan.inputs.empty())
      errors->push_back(path + ": needs inputs: the stages to wait for (the evaluations)");
  }
  std::string Description() const override {
    return "writes the job's HTML report: tables, claims, curves, previews";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    fs::create_directories(ctx.output_dir());
    std::string job;
    for (const auto& input : ctx.spec.inputs()) {
      if (input.dirs_size() > 0) job = fs::path(input.dirs(0)).parent_path().parent_path().string();
    }
    if (job.empty())
      return TaskReport::BadInput("report: needs inputs (the job's evaluation stages)");
    report::ReportOptions options;
    options.job_dir = job;
    options.out_path = ctx.output_dir() + "/report.html";
    options.history = p.value("history", std::string());
    if (!options.history.empty() && !fs::exists(options.history))
      options.history.clear();  // nothing recorded yet
    options.title = p.value("title", ctx.spec.job_name() + "-" + std::to_string(ctx.spec.job_id()));
    options.previews = p.value("previews", true);
    options.panel_size = static_cast<int>(p.value("panel_size", int64_t{200}));
    // Paper files beside the built-in ones (configs/papers/*.yaml's format): a path or a list.
    const json papers = p.value("papers", json::array());
    for (const json& file : papers.is_array() ? papers : json::array({papers})) {
      if (!file.is_string())
        return TaskReport::BadInput("report: params.papers must be a path or a list of paths");
      options.papers.push_back(file.get<std::string>());
    }
    auto summary = report::WriteReport(options);
    if (!summary.ok()) return TaskReport::FromStatus(summary.status().WithContext("report"));
    json claims = json::array();
    for (const report::ClaimCheck& c : summary->claims)
      claims.push_back(
          {{"paper", c.paper}, {"claim", c.claim}, {"verdict", c.verdict}, {"detail", c.detail}});
    const json out = {{"report", "report.html"},
                      {"tables", summary->tables},
                      {"images", summary->images},
                      {"claims", claims},
                      {"methods", summary->methods}};  // by evaluation kind
    if (Status st = WriteFileAtomic(ctx.output_dir() + "/report.json", out.dump(1) + "\n");
        !st.ok())
      return TaskReport::Error(st.message());
    MP_LOG(kInfo, "report") << "report of " << job << ": " << summary->tables << " tables, "
                            << summary->images << " images";
    TaskReport report = TaskReport::Ok();
    report.metrics["tables"] = summary->tables;
    report.metrics["images"] = summary->images;
    return report;
  }
};

}  // namespace

MP_STAGE_KIND("report", ReportStage);

}  // namespace motionpipe::stages
