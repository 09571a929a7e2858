// `synth`: SINC's synthetic pairs as recipes, sharded with a seed per shard, plus a summary.
#include "motionpipe/sinc/synth.h"

#include <filesystem>
#include <map>

#include "inputs.h"
#include "motionpipe/base/file.h"
#include "motionpipe/sinc/spans.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

std::string FindSpans(const TaskContext& ctx, const json& p) {
  if (p.contains("spans")) return p["spans"].get<std::string>();
  for (const std::string& dir : StageDirs(ctx, "")) {
    if (fs::exists(dir + "/spans.npz")) return dir + "/spans.npz";
  }
  return "";
}

// `synth`: shard i makes pairs [i * shard_size, ...) of params.pairs; the reduce task sums up.
class SynthStage : public StageExecutor {
 public:
  // Shards of shard_size pairs, then a reduce task (the summary).
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    const auto& p = plan.params;
    const int64_t pairs =
        p.contains("pairs") && p["pairs"].is_number_integer() ? p["pairs"].get<int64_t>() : 10000;
    const int64_t shard = p.contains("shard_size") && p["shard_size"].is_number_integer()
                              ? p["shard_size"].get<int64_t>()
                              : 50000;
    if (pairs < 1 || shard < 1) {
      errors->push_back(path + ".params: pairs and shard_size must be positive integers");
      return;
    }
    plan.shards = static_cast<int>((pairs + shard - 1) / shard);
    plan.reduce = true;
    if (!p.contains("spans") && plan.inputs.empty())
      errors->push_back(path + ": needs an input `singles` stage or params.spans");
    auto options = sinc::SynthOptionsFromJson(p, path + ".params");
    if (!options.ok()) errors->push_back(options.status().message());
  }
  std::string Description() const override {
    return "SINC synthetic pairs: compatible singles composed, checked, stored as recipes";
  }
  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (ctx.spec.reduce()) return Summarize(ctx);
    const std::string spans_path = FindSpans(ctx, p);
    if (spans_path.empty())
      return TaskReport::BadInput(
          "synth: no spans.npz (params.spans, or an input `singles` stage)");
    auto table = sinc::ReadSpans(spans_path);
    if (!table.ok()) return TaskReport::FromStatus(table.status());
    json merged = p;
    if (!merged.contains("seed")) merged["seed"] = ctx.spec.seed();
    auto options = sinc::SynthOptionsFromJson(merged, "params");
    if (!options.ok()) return TaskReport::FromStatus(options.status());
    const int64_t total = p.value("pairs", int64_t{10000});
    const int64_t shard_size = p.value("shard_size", int64_t{50000});
    const int64_t begin = static_cast<int64_t>(ctx.spec.index()) * shard_size;
    const int64_t count = std::min(shard_size, total - begin);
    if (count <= 0) return TaskReport::Ok();
    auto report = sinc::SynthesizeShard(*table, *options, ctx.spec.index(), count, ctx.threads,
                                        ctx.output_dir());
    if (!report.ok()) return TaskReport::FromStatus(report.status());
    // The spans file the recipes index, for loaders and exports.
    const json source = {{"spans", fs::absolute(spans_path).string()},
                         {"first_pair", begin},
                         {"pairs", report->pairs}};
    if (Status s = WriteFileAtomic(ctx.output_dir() + "/source.json", source.dump(1) + "\n", false);
        !s.ok())
      return TaskReport::Error(s.message());
    TaskReport out;
    out.metrics["pairs"] = static_cast<double>(report->pairs);
    out.metrics["pairs_per_second"] =
        static_cast<double>(report->pairs) / std::max(report->seconds, 1e-9);
    out.metrics["peak_rss_bytes"] = static_cast<double>(report->peak_rss_bytes);
    return out;
  }

 private:
  static TaskReport Summarize(TaskContext& ctx) {
    int64_t pairs = 0, candidates = 0, bytes = 0;
    double seconds = 0;
    std::map<std::string, int64_t> dropped;
    struct Rss {
      int64_t tasks = 0, first = 0, last = 0, peak = 0;
    };
    std::map<int64_t, Rss>
        rss;  // per worker process: resident memory after its first and last shard
    json shards = json::array();
    for (const std::string& dir : ctx.spec.shard_dirs()) {
      auto text = ReadFile(dir + "/stats.json");
      if (!text.ok()) continue;  // a shard with no pairs to make
      const json stats = json::parse(*text, nullptr, false);
      if (!stats.is_object()) return TaskReport::BadInput(dir + "/stats.json: not JSON");
      pairs += stats.value("pairs", int64_t{0});
      candidates += stats.value("candidates", int64_t{0});
      bytes += stats.value("bytes", int64_t{0});
      seconds += stats.value("seconds", 0.0);
      for (const auto& item : stats["dropped"].items())
        dropped[item.key()] += item.value().get<int64_t>();
      const int64_t pid = stats.value("pid", int64_t{0});
      Rss& r = rss[pid];
      const int64_t now = stats.value("rss_bytes", int64_t{0});
      if (r.tasks++ == 0) r.first = now;
      r.last = now;
      r.peak = std::max(r.peak, stats.value("peak_rss_bytes", int64_t{0}));
      shards.push_back({{"dir", fs::path(dir).filename().string()},
                        {"pairs", stats.value("pairs", int64_t{0})}});
    }
    json workers = json::array();
    for (const auto& [pid, r] : rss) {
      workers.push_back({{"pid", pid},
                         {"shards", r.tasks},
                         {"rss_after_first_shard", r.first},
                         {"rss_after_last_shard", r.last},
                         {"peak_rss", r.peak}});
    }
    const json summary = {
        {"pairs", pairs},
        {"candidates", candidates},
        {"dropped", dropped},
        {"kept_fraction",
         candidates > 0 ? static_cast<double>(pairs) / static_cast<double>(candidates) : 0.0},
        {"recipe_bytes", bytes},
        {"bytes_per_pair",
         pairs > 0 ? static_cast<double>(bytes) / static_cast<double>(pairs) : 0.0},
        {"task_seconds", seconds},
        {"pairs_per_task_second", seconds > 0 ? static_cast<double>(pairs) / seconds : 0.0},
        {"workers", workers},
        {"shards", shards}};
    std::filesystem::create_directories(ctx.output_dir());
    if (Status s =
            WriteFileAtomic(ctx.output_dir() + "/summary.json", summary.dump(1) + "\n", false);
        !s.ok())
      return TaskReport::Error(s.message());
    TaskReport report;
    report.metrics["pairs"] = static_cast<double>(pairs);
    return report;
  }
};

}  // namespace

MP_STAGE_KIND("synth", SynthStage);

}  // namespace motionpipe::stages
