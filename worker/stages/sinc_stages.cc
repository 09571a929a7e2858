// SINC's data stages: `singles` (action spans from BABEL + AMASS, labelled with body parts) and
// `synth` (synthetic pairs as recipes, sharded with a seed per shard, plus a summary).
#include <filesystem>
#include <map>

#include "../executor.h"
#include "../labelers.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/sinc/spans.h"
#include "motionpipe/sinc/synth.h"

namespace motionpipe::worker {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Every directory the task's inputs committed (results first).
std::vector<std::string> AllInputDirs(const TaskContext& ctx) {
  std::vector<std::string> dirs;
  for (const auto& input : ctx.spec.inputs()) {
    if (!input.result_dir().empty()) dirs.push_back(input.result_dir());
    for (const auto& d : input.dirs()) dirs.push_back(d);
  }
  return dirs;
}

std::vector<std::string> StringList(const json& v) {
  std::vector<std::string> out;
  if (v.is_string()) out.push_back(v.get<std::string>());
  if (v.is_array()) {
    for (const auto& item : v) out.push_back(item.get<std::string>());
  }
  return out;
}

// `dataset`: real data in place of the procedural corpus, laid out as the corpus stage lays out its
// result, so that every later stage runs unchanged: DIR/motionfix/triplets-*.npz (converted
// MotionFix, tools/motionfix_convert.py), DIR/babel/{train,val,test}.json (BABEL) and
// DIR/amass_root (the AMASS root BABEL's feat_p paths are relative to). Files are linked, not
// copied. params: motionfix (converted .npz files or directories of them), babel (a directory
// holding train/val/test.json, or the files), amass_root. Either source may be absent.
class DatasetStage : public StageExecutor {
 public:
  // One task.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    const auto& p = plan.params;
    if (!p.contains("motionfix") && !p.contains("babel"))
      errors->push_back(path +
                        ".params: give motionfix (converted .npz files) and/or babel + amass_root");
    if (p.contains("babel") && !p.contains("amass_root"))
      errors->push_back(path + ".params.amass_root: required with babel (the AMASS directory)");
  }
  std::string Description() const override {
    return "links real data (converted MotionFix, BABEL + AMASS) in the corpus layout";
  }
  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    const std::string out = ctx.output_dir();
    fs::create_directories(out);
    const auto link = [](const std::string& target, const std::string& path) -> Status {
      std::error_code ec;
      fs::create_directories(fs::path(path).parent_path(), ec);
      fs::create_symlink(fs::absolute(target), path, ec);
      if (ec) return IoError(path + ": cannot link to " + target + ": " + ec.message());
      return Status::Ok();
    };
    json manifest = {{"motionfix", json::array()}, {"babel", json::array()}};
    for (const std::string& entry : StringList(p.value("motionfix", json()))) {
      std::vector<std::string> files;
      if (fs::is_directory(entry)) {
        for (const auto& e : fs::directory_iterator(entry)) {
          if (e.path().extension() == ".npz") files.push_back(e.path().string());
        }
      } else if (fs::is_regular_file(entry)) {
        files.push_back(entry);
      } else {
        return TaskReport::BadInput("dataset: params.motionfix: " + entry + " does not exist");
      }
      std::sort(files.begin(), files.end());
      for (const std::string& f : files) {
        auto columns =
            ReadTripletColumns(f, {0, -1, false, false});  // checked now, not in a later stage
        if (!columns.ok()) return TaskReport::BadInput("dataset: " + columns.status().message());
        const std::string name = fs::path(f).stem().string();
        const std::string linked = out + "/motionfix/" +
                                   (name.rfind("triplets", 0) == 0 ? name : "triplets-" + name) +
                                   ".npz";
        if (Status st = link(f, linked); !st.ok())
          return TaskReport::BadInput("dataset: " + st.message());
        manifest["motionfix"].push_back(
            {{"file", fs::absolute(f).string()}, {"triplets", columns->rows}});
      }
    }
    const json babel_param = p.value("babel", json());
    std::vector<std::pair<std::string, std::string>> babel;  // split file -> name
    for (const std::string& entry : StringList(babel_param)) {
      if (fs::is_directory(entry)) {
        for (const char* split : {"train", "val", "test"}) {
          if (fs::exists(entry + "/" + split + ".json"))
            babel.push_back({entry + "/" + split + ".json", split});
        }
      } else if (fs::is_regular_file(entry)) {
        babel.push_back({entry, fs::path(entry).stem().string()});
      } else {
        return TaskReport::BadInput("dataset: params.babel: " + entry + " does not exist");
      }
    }
    for (const auto& [file, split] : babel) {
      if (split != "train" && split != "val" && split != "test") {
        return TaskReport::BadInput("dataset: params.babel: " + file +
                                    ": BABEL files are named train.json, val.json or test.json");
      }
      if (Status st = link(file, out + "/babel/" + split + ".json"); !st.ok())
        return TaskReport::BadInput("dataset: " + st.message());
      manifest["babel"].push_back(fs::absolute(file).string());
    }
    if (!babel.empty()) {
      const std::string root = p.value("amass_root", std::string());
      if (root.empty() || !fs::is_directory(root))
        return TaskReport::BadInput(
            "dataset: params.amass_root: the AMASS directory BABEL's feat_p paths start from");
      if (Status st = WriteFileAtomic(out + "/amass_root", fs::absolute(root).string()); !st.ok())
        return TaskReport::Error(st.message());
      manifest["amass_root"] = fs::absolute(root).string();
    }
    if (manifest["motionfix"].empty() && babel.empty())
      return TaskReport::BadInput("dataset: give params.motionfix and/or params.babel");
    if (Status st = WriteFileAtomic(out + "/manifest.json", manifest.dump(1) + "\n"); !st.ok())
      return TaskReport::Error(st.message());
    return TaskReport::Ok();
  }
};

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
      for (const std::string& dir : AllInputDirs(ctx)) {
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
      for (const std::string& dir : AllInputDirs(ctx)) {
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

std::string FindSpans(const TaskContext& ctx, const json& p) {
  if (p.contains("spans")) return p["spans"].get<std::string>();
  for (const std::string& dir : AllInputDirs(ctx)) {
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
    if (ctx.spec.reduce()) return Summarise(ctx);
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
    auto report = sinc::SynthesiseShard(*table, *options, ctx.spec.index(), count, ctx.threads,
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
  static TaskReport Summarise(TaskContext& ctx) {
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

void RegisterSincExecutors(ExecutorRegistry* registry, const PluginHost* plugins) {
  registry->Register("dataset", std::make_unique<DatasetStage>());
  registry->Register("singles", std::make_unique<SinglesStage>(plugins));
  registry->Register("synth", std::make_unique<SynthStage>());
}

}  // namespace motionpipe::worker
