// `singles`: SINC's single-action spans, labelled with body parts.
#include <filesystem>
#include <map>

#include "inputs.h"
#include "labelers.h"
#include "motionpipe/base/file.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// `singles`: the spans table (spans.h) of a corpus or of BABEL + AMASS, every action text labelled.
class SinglesStage : public StageExecutor {
 public:
  // One task.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    const auto& p = plan.params;
    if (!p.contains("babel") && plan.inputs.empty())
      errors->push_back(path + ": needs an input stage (a corpus) or params.babel");
    if (p.contains("labeler") && !p["labeler"].is_string())
      errors->push_back(path + ".params.labeler: must be a labeler name");
  }
  explicit SinglesStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "single-action and two-action spans from BABEL + AMASS, body parts labelled";
  }
  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    std::vector<std::string> babel = StringList(p.value("babel", json()));
    std::string amass_root = p.value("amass_root", std::string());
    if (babel.empty()) {  // a corpus from an input stage: DIR/babel/{train,val,test}.json, AMASS
                          // under DIR
      for (const std::string& dir : StageDirs(ctx, "")) {
        for (const char* split : {"train", "val", "test"}) {
          const std::string file = dir + "/babel/" + split + ".json";
          if (fs::exists(file)) babel.push_back(file);
        }
        if (!babel.empty()) {
          // A `dataset` stage names the user's AMASS root in DIR/amass_root; a corpus holds its
          // own.
          if (amass_root.empty()) {
            auto named = ReadFile(dir + "/amass_root");
            amass_root = named.ok() && !named->empty() ? *named : dir;
          }
          break;
        }
      }
    }
    if (babel.empty())
      return TaskReport::BadInput(
          "singles: no BABEL files (params.babel, or an input stage holding babel/*.json)");
    sinc::SpanExtraction extraction;
    extraction.fps = p.value("fps", 30.0);
    extraction.sweep.min_frames = p.value("min_frames", 15);
    extraction.sweep.max_frames = p.value("max_frames", 600);
    extraction.keep_pairs = p.value("keep_pairs", true);
    int64_t skipped = 0;
    std::string problem;
    auto table = sinc::ExtractBabelSpans(babel, amass_root, extraction, &skipped, &problem);
    if (!table.ok()) return TaskReport::FromStatus(table.status());
    if (table->size() == 0)
      return TaskReport::BadInput("singles: no spans (" + std::to_string(skipped) +
                                  " sequences skipped: " + problem + ")");

    // Labels for every distinct text, from the configured labeler.
    const std::string labeler_name = p.value("labeler", std::string("lexicon"));
    json labeler_config = p.value("labeler_config", json::object());
    if (labeler_name == "learned" && !labeler_config.contains("model")) {
      for (const std::string& dir : StageDirs(ctx, "")) {
        if (fs::exists(dir + "/learned_labeler.pt")) labeler_config["model"] = dir;
      }
    }
    auto labeler = MakeLabeler(labeler_name, labeler_config, plugins_);
    if (!labeler.ok()) return TaskReport::FromStatus(labeler.status());
    if ((*labeler)->NeedsMotion())
      return TaskReport::BadInput("singles: labeler '" + labeler_name +
                                  "' labels motions; choose a text labeler");
    std::map<std::string, PartSet> parts;
    for (int64_t i = 0; i < table->size(); ++i) {
      parts[table->text_a[static_cast<size_t>(i)]] = 0;
      if (!table->single(i)) parts[table->text_b[static_cast<size_t>(i)]] = 0;
    }
    std::vector<labels::LabelInput> inputs;
    for (const auto& [text, unused] : parts) inputs.push_back({text, nullptr});
    auto labelled = (*labeler)->Label(inputs);
    if (!labelled.ok()) return TaskReport::FromStatus(labelled.status());
    size_t k = 0;
    for (auto& [text, set] : parts) set = (*labelled)[k++];
    std::map<std::string, int64_t> per_split, per_parts;
    int64_t singles = 0, pairs = 0, frames = 0;
    for (int64_t i = 0; i < table->size(); ++i) {
      const auto u = static_cast<size_t>(i);
      table->parts_a[u] = parts[table->text_a[u]];
      if (!table->single(i)) table->parts_b[u] = parts[table->text_b[u]];
      ++per_split[table->splits[u]];
      (table->single(i) ? singles : pairs) += 1;
      if (table->single(i)) ++per_parts[PartSetToString(table->parts_a[u])];
      frames += table->frames(i);
    }
    table->labeler = labeler_name;
    std::filesystem::create_directories(ctx.output_dir());
    if (Status s = sinc::WriteSpans(ctx.output_dir() + "/spans.npz", *table); !s.ok())
      return TaskReport::Error(s.message());
    const json stats = {
        {"spans", table->size()},  {"singles", singles},        {"pairs", pairs},
        {"frames", frames},        {"texts", parts.size()},     {"labeler", labeler_name},
        {"by_split", per_split},   {"single_parts", per_parts}, {"sequences_skipped", skipped},
        {"first_problem", problem}};
    if (Status s = WriteFileAtomic(ctx.output_dir() + "/stats.json", stats.dump(1) + "\n", false);
        !s.ok())
      return TaskReport::Error(s.message());
    TaskReport report;
    report.metrics["singles"] = static_cast<double>(singles);
    report.metrics["pairs"] = static_cast<double>(pairs);
    return report;
  }

 private:
  const PluginHost* plugins_;
};

}  // namespace

MP_STAGE_KIND("singles", SinglesStage);

}  // namespace motionpipe::stages
