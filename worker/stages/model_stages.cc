// Stages that run trained models through the torch-free generator interface (generators.h):
// `edit` edits the test split's triplets with an editing checkpoint (MDT, TMED, MDM, MDM-BP),
// sharded over workers, writing the edited motions as a clip file per task;
// `eval_edit` scores an edit stage's motions with an evaluator checkpoint (TMR): motion-to-motion
// retrieval generated-to-target and generated-to-source (SimMotionEdit Table 1), and physical
// plausibility of the edits and of the targets;
// `generate` generates the test split's action texts (SINC: two-action pairs by default) with a
// text-to-motion checkpoint, at each ground-truth motion's length, sharded;
// `eval_generate` scores them against the ground truth (SINC Tables 2-3): TEMOS score, APE/AVE,
// text-to-motion and motion-to-motion retrieval, diversity, plausibility.
//
// params (edit): model (the input stage holding the checkpoint; default: the input that has one),
//   split (test), limit (0 = all), batch (8), sampler (ddpm | ddim), steps (DDIM steps), seed,
//   body_parts (MDM-BP), options (merged into the generator's configuration)
#include <glob.h>
#include <prometheus/gateway.h>
#include <prometheus/gauge.h>
#include <prometheus/registry.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <filesystem>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <tuple>

#include "../executor.h"
#include "../generators.h"
#include "metric_history.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/base/log.h"
#include "motionpipe/base/random.h"
#include "motionpipe/eval/metrics.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/labels/labeler.h"
#include "motionpipe/motion/plausibility.h"
#include "motionpipe/render/motion_render.h"
#include "motionpipe/sinc/composition.h"
#include "motionpipe/sinc/spans.h"
#include "motionpipe/sinc/texts.h"
#include "motionpipe/skeleton/skeleton.h"
#include "report.h"

namespace motionpipe::worker {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Triplet files of the inputs (TripletFilesIn), sorted. An input with a result directory (a
// corpus) is read from there only: its task directories hold the same triplets as shards.
std::vector<std::string> TripletFiles(const TaskContext& ctx) {
  std::vector<std::string> files;
  const auto add = [&](const std::string& dir) {
    const std::vector<std::string> found = TripletFilesIn(dir);
    files.insert(files.end(), found.begin(), found.end());
    return !found.empty();
  };
  for (const auto& input : ctx.spec.inputs()) {
    if (!input.result_dir().empty() && add(input.result_dir())) continue;
    for (const auto& dir : input.dirs()) add(dir);
  }
  std::sort(files.begin(), files.end());
  files.erase(std::unique(files.begin(), files.end()), files.end());
  return files;
}

// A checkpoint named by a stage parameter: an input stage's name, or a path pattern (anything with
// a '/', e.g. "out/train_mdt-*/mdt") whose newest checkpoint is taken: a scheduled evaluation of
// the latest training job.
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

Motion SideMotion(const TripletColumns& c, int64_t row, bool source) {
  const auto& side = source ? c.source : c.target;
  const int64_t begin = side.offsets[static_cast<size_t>(row)],
                end = side.offsets[static_cast<size_t>(row) + 1];
  Motion m;
  m.fps = c.fps[static_cast<size_t>(row)];
  m.poses.assign(side.poses + begin * side.joints * 3, side.poses + end * side.joints * 3);
  m.trans.assign(side.trans + begin * 3, side.trans + end * 3);
  return m;
}

json ScoresJson(const eval::RetrievalScores& s) {
  return {
      {"R@1", s.r1}, {"R@2", s.r2}, {"R@3", s.r3}, {"AvgR", s.avg_rank}, {"queries", s.queries}};
}

// Physical plausibility averaged over motions: foot skating, floor penetration, floating, jerk.
json MeanPlausibility(const std::vector<Motion>& motions) {
  double skate = 0, penetration = 0, floating = 0, jerk = 0;
  for (const Motion& m : motions) {
    const auto r = EvaluateMotionPlausibility(Skeleton::Smpl22(), m);
    skate += r.foot_skate_ratio, penetration += r.penetration_mean, floating += r.float_ratio,
        jerk += r.jerk_mean;
  }
  const double n = static_cast<double>(std::max<size_t>(1, motions.size()));
  return json{{"foot_skate_ratio", skate / n},
              {"penetration_mean_m", penetration / n},
              {"float_ratio", floating / n},
              {"jerk_mean", jerk / n}};
}

// The generator of the checkpoint named by params.model (see FindCheckpoint), with `options`.
Result<GeneratorPtr> OpenModel(const TaskContext& ctx, const PluginHost& plugins,
                               const json& options, std::string* checkpoint) {
  *checkpoint = FindCheckpoint(ctx, ctx.params.value("model", std::string()));
  if (checkpoint->empty()) return NotFound("no input holds a checkpoint (a train stage's model/)");
  return LoadGenerator(plugins, *checkpoint, options);
}

// preview.npz next to metrics.json: the first evaluated example's motions as clips (ids = roles:
// "source", "edited", "target"; "generated", "truth"), each with its text, for the report's
// renders.
Status WritePreview(const TaskContext& ctx,
                    const std::vector<std::pair<std::string, const Motion*>>& roles,
                    const std::string& text, const std::string& example) {
  std::vector<Clip> clips;
  for (const auto& [role, motion] : roles) {
    Clip clip;
    clip.id = role;
    clip.source = example;
    clip.motion = *motion;
    clip.texts = {text};
    clips.push_back(std::move(clip));
  }
  return WriteClips(ctx.output_dir() + "/preview.npz", clips);
}

// Cosine similarity of two embeddings (0 for a zero vector).
double Cosine(const std::vector<float>& a, const std::vector<float>& b) {
  double dot = 0, na = 0, nb = 0;
  for (size_t k = 0; k < a.size(); ++k) dot += a[k] * b[k], na += a[k] * a[k], nb += b[k] * b[k];
  return dot / std::max(1e-12, std::sqrt(na * nb));
}

// Embeddings from an encoder's rows.
eval::Embeddings ToEmbeddings(const std::vector<std::vector<float>>& rows) {
  eval::Embeddings e{static_cast<int64_t>(rows.size()),
                     rows.empty() ? 0 : static_cast<int64_t>(rows[0].size()),
                     {}};
  for (const auto& row : rows) e.values.insert(e.values.end(), row.begin(), row.end());
  return e;
}

// What an evaluated stage's summary (edits.json, generate.json) says: the model's name and
// checkpoint.
void ReadSummary(const std::string& path, std::string* method, std::string* checkpoint) {
  auto text = ReadFile(path);
  if (!text.ok()) return;
  const json summary = json::parse(*text, nullptr, false);
  if (summary.is_discarded()) return;
  if (method->empty()) *method = summary.value("model", std::string());
  if (checkpoint->empty()) *checkpoint = summary.value("checkpoint", std::string());
}

class EditStage : public StageExecutor {
 public:
  // `shards` tasks (default 2), each every count-th triplet of the test split.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    if (!plan.shards_set) plan.shards = 2;
    plan.reduce = false;
    if (plan.inputs.empty())
      errors->push_back(path +
                        ": needs inputs: the train stage of the editor and a stage with triplets");
    const auto& p = plan.params;
    if (p.contains("sampler") && p["sampler"] != "ddpm" && p["sampler"] != "ddim")
      errors->push_back(path + ".params.sampler: ddpm or ddim");
    LongLease(plan);
  }
  explicit EditStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "edits the test triplets with an editing checkpoint, sharded";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("edit: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    json options = p.value("options", json::object());
    if (p.value("body_parts", false)) options["body_parts"] = true;
    std::string checkpoint;
    auto generator = OpenModel(ctx, *plugins_, options, &checkpoint);
    if (!generator.ok()) return TaskReport::BadInput("edit: " + generator.status().message());
    const std::string split = p.value("split", std::string("test"));
    const int64_t limit = p.value("limit", int64_t{0});
    const int batch_size = std::max(1, p.value("batch", 8));
    // Every triplet of the split, in file and row order; this task takes every count-th one.
    struct Item {
      size_t file;
      int64_t row;
    };
    std::vector<TripletColumns> files;
    std::vector<Item> items;
    for (const std::string& path : TripletFiles(ctx)) {
      auto columns = ReadTripletColumns(path, {0, -1, true, false});
      if (!columns.ok()) return TaskReport::BadInput(columns.status().message());
      for (int64_t r = 0; r < columns->rows; ++r) {
        if (columns->splits[static_cast<size_t>(r)] == split) items.push_back({files.size(), r});
      }
      files.push_back(std::move(*columns));
    }
    if (items.empty())
      return TaskReport::BadInput("edit: no triplets of split '" + split + "' in the inputs");
    if (limit > 0 && static_cast<int64_t>(items.size()) > limit)
      items.resize(static_cast<size_t>(limit));
    std::vector<Item> mine;
    std::vector<uint64_t>
        place;  // each item's place in the split: its sampling seed, whatever the batching
    for (size_t k = static_cast<size_t>(ctx.spec.index()); k < items.size();
         k += static_cast<size_t>(std::max(1, ctx.spec.count()))) {
      mine.push_back(items[k]);
      place.push_back(k);
    }
    // Batches of similar lengths: a batch is padded to its longest source.
    std::vector<size_t> order(mine.size());
    for (size_t k = 0; k < order.size(); ++k) order[k] = k;
    const auto length = [&](size_t k) {
      const auto& o = files[mine[k].file].source.offsets;
      return o[mine[k].row + 1] - o[mine[k].row];
    };
    std::stable_sort(order.begin(), order.end(),
                     [&](size_t a, size_t b) { return length(a) > length(b); });
    {
      std::vector<Item> sorted_items;
      std::vector<uint64_t> sorted_places;
      for (size_t k : order) sorted_items.push_back(mine[k]), sorted_places.push_back(place[k]);
      mine = std::move(sorted_items);
      place = std::move(sorted_places);
    }
    std::vector<Clip> clips;
    const auto started = std::chrono::steady_clock::now();
    for (size_t at = 0; at < mine.size(); at += static_cast<size_t>(batch_size)) {
      if (ctx.cancelled()) return TaskReport::Error("cancelled");
      const size_t end = std::min(mine.size(), at + static_cast<size_t>(batch_size));
      std::vector<Motion> sources;
      for (size_t k = at; k < end; ++k)
        sources.push_back(SideMotion(files[mine[k].file], mine[k].row, true));
      std::vector<plugin::GenerateRequest> requests;
      for (size_t k = at; k < end; ++k) {
        const TripletColumns& c = files[mine[k].file];
        plugin::GenerateRequest r;
        r.texts = {c.texts[static_cast<size_t>(mine[k].row)]};
        r.source = &sources[k - at];
        r.seed = MixSeed(ctx.spec.seed(), place[k]);
        r.sampler = p.value("sampler", std::string("ddpm"));
        r.steps = p.value("steps", 0);
        requests.push_back(r);
      }
      auto edited = (*generator)->GenerateBatch(requests);
      if (!edited.ok()) return TaskReport::Error(edited.status().message());
      for (size_t k = at; k < end; ++k) {
        const TripletColumns& c = files[mine[k].file];
        Clip clip;
        clip.id = c.ids[static_cast<size_t>(mine[k].row)];
        clip.source = "edit:" + (*generator)->Name() + ":" + c.origin + "#" +
                      std::to_string(c.first_row + mine[k].row);
        clip.motion = std::move((*edited)[k - at]);
        clip.texts = {c.texts[static_cast<size_t>(mine[k].row)]};
        clips.push_back(std::move(clip));
      }
      if (ctx.on_metric) ctx.on_metric("edited", static_cast<double>(clips.size()));
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (!clips.empty()) {
      if (Status s = WriteClips(ctx.output_dir() + "/edited.npz", clips); !s.ok())
        return TaskReport::Error(s.message());
    }
    const json summary = {
        {"model", (*generator)->Name()},
        {"checkpoint", checkpoint},
        {"split", split},
        {"edited", clips.size()},
        {"seconds", seconds},
        {"motions_per_second", static_cast<double>(clips.size()) / std::max(seconds, 1e-9)},
        {"sampler", p.value("sampler", std::string("ddpm"))},
        {"steps", p.value("steps", 0)}};
    if (Status s = WriteFileAtomic(ctx.output_dir() + "/edits.json", summary.dump(1) + "\n");
        !s.ok())
      return TaskReport::Error(s.message());
    TaskReport out = TaskReport::Ok();
    out.metrics["edited"] = static_cast<double>(clips.size());
    out.metrics["motions_per_second"] = summary["motions_per_second"].get<double>();
    return out;
  }

 private:
  const PluginHost* plugins_;
};

// The evaluation history (params.history: a SQLite file; off when absent): appends the tracked
// metrics, adds "regressions" to `metrics`, logs each one, and (fail_on_regression) fails the task,
// which fails the job: the exit code of `run` and `wait`. A regression is a metric more than
// params.regression_margin (absolute, in the metric's units) below its best earlier value.
struct Tracked {
  const char* name;
  double value;
  bool higher_is_better;
};

// Pushes this evaluation's headline metrics and its regressions to a Prometheus Pushgateway
// ("http://host:port"), grouped by job name and stage: motionpipe_eval_metric{method, metric},
// motionpipe_eval_regression{method, metric} (1 when it regressed) and motionpipe_eval_regressions.
// A gateway that cannot be reached is logged and recorded, not fatal: the metrics are on disk.
json PushToGateway(const TaskContext& ctx, const std::string& url, const std::string& method,
                   const std::vector<Tracked>& tracked,
                   const std::vector<report::Regression>& regressions) {
  const size_t colon = url.rfind(':');
  if (url.empty() || colon == std::string::npos || colon + 1 >= url.size() ||
      url.find("//") == std::string::npos) {
    MP_LOG(kWarn, "eval") << "pushgateway '" << url << "': expected http://host:port; not pushed";
    return {{"url", url}, {"error", "expected http://host:port"}};
  }
  auto registry = std::make_shared<prometheus::Registry>();
  auto& value = prometheus::BuildGauge()
                    .Name("motionpipe_eval_metric")
                    .Help("Headline evaluation metrics of the last run")
                    .Register(*registry);
  auto& regressed = prometheus::BuildGauge()
                        .Name("motionpipe_eval_regression")
                        .Help("1 when the metric regressed against its best")
                        .Register(*registry);
  auto& count = prometheus::BuildGauge()
                    .Name("motionpipe_eval_regressions")
                    .Help("Regressions found by the last evaluation run")
                    .Register(*registry);
  for (const Tracked& t : tracked) {
    value.Add({{"method", method}, {"metric", t.name}}).Set(t.value);
    const bool bad = std::any_of(regressions.begin(), regressions.end(),
                                 [&](const report::Regression& r) { return r.metric == t.name; });
    regressed.Add({{"method", method}, {"metric", t.name}}).Set(bad ? 1 : 0);
  }
  count.Add({{"method", method}}).Set(static_cast<double>(regressions.size()));
  prometheus::Gateway gateway(url.substr(0, colon), url.substr(colon + 1), "motionpipe_eval",
                              {{"pipeline", ctx.spec.job_name()}, {"stage", ctx.spec.stage()}});
  gateway.RegisterCollectable(registry);
  const int status = gateway.Push();
  if (status < 200 || status >= 300) {
    MP_LOG(kWarn, "eval") << "pushgateway " << url << ": push failed (HTTP status " << status
                          << ")";
  } else {
    MP_LOG(kInfo, "eval") << "pushed " << tracked.size() << " metric(s) and " << regressions.size()
                          << " regression(s) to " << url;
  }
  return {{"url", url}, {"status", status}};
}

std::optional<TaskReport> RecordHistory(const TaskContext& ctx, json* metrics,
                                        const std::string& method, const std::string& checkpoint,
                                        const std::vector<std::string>& ids,
                                        const std::vector<Tracked>& tracked) {
  const json& p = ctx.params;
  const std::string path = p.value("history", std::string());
  if (path.empty()) return std::nullopt;
  std::string data;
  for (const auto& id : ids) data += id + "\n";
  auto config = ReadFile(layout::ModelConfigFile(checkpoint));
  std::vector<report::MetricRecord> records;
  for (const Tracked& t : tracked) {
    report::MetricRecord r;
    r.method = method;
    r.metric = t.name;
    r.value = t.value;
    r.higher_is_better = t.higher_is_better;
    r.checkpoint = checkpoint;
    r.config_hash = config.ok() ? report::HashText(*config) : "";
    r.data_hash = report::HashText(data);
    r.job = std::to_string(ctx.spec.job_id());
    r.time_unix = static_cast<int64_t>(std::time(nullptr));
    records.push_back(r);
  }
  auto regressions = report::AppendAndCompare(path, records, p.value("regression_margin", 0.0));
  if (!regressions.ok()) return TaskReport::Error(regressions.status().message());
  (*metrics)["history"] = path;
  (*metrics)["regressions"] = json::array();
  for (const auto& r : *regressions) {
    (*metrics)["regressions"].push_back({{"metric", r.metric},
                                         {"value", r.value},
                                         {"best", r.best},
                                         {"best_checkpoint", r.best_checkpoint}});
    MP_LOG(kWarn, "eval") << "regression: " << r.Describe();
  }
  if (p.contains("pushgateway"))
    (*metrics)["pushgateway"] =
        PushToGateway(ctx, p.value("pushgateway", std::string()), method, tracked, *regressions);
  if (!regressions->empty() && p.value("fail_on_regression", false)) {
    (void)WriteFileAtomic(layout::MetricsFile(ctx.output_dir()),
                          metrics->dump(1) + "\n");  // for the record; the task fails
    return TaskReport::BadInput("regression: " + regressions->front().Describe() +
                                (regressions->size() > 1
                                     ? " (and " + std::to_string(regressions->size() - 1) + " more)"
                                     : ""));
  }
  return std::nullopt;
}

// The scoring's wall time (loading the evaluators, encoding, metrics) and its throughput in motions
// scored (generated and reference motions alike) per second: the evaluation benchmark reads these.
void AddTiming(json* metrics, std::chrono::steady_clock::time_point started,
               size_t motions_scored) {
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  (*metrics)["seconds"] = seconds;
  (*metrics)["motions_scored"] = motions_scored;
  (*metrics)["motions_scored_per_second"] =
      seconds > 0 ? static_cast<double>(motions_scored) / seconds : 0.0;
}

// Writes metrics.json; the task's report carries the number of regressions.
TaskReport WriteMetrics(const TaskContext& ctx, const json& metrics) {
  if (Status st = WriteFileAtomic(layout::MetricsFile(ctx.output_dir()), metrics.dump(1) + "\n");
      !st.ok())
    return TaskReport::Error(st.message());
  TaskReport out = TaskReport::Ok();
  out.metrics["regressions"] =
      metrics.contains("regressions") ? static_cast<double>(metrics["regressions"].size()) : 0.0;
  return out;
}

// Retrieval of edits `g` among the targets and among the sources (batches and all), and how far the
// edits move towards their targets: generated-to-target minus generated-to-source R@1 (the copy of
// the source scores about -(target-to-source R@1), the target itself about +that).
Result<json> EditRetrieval(const eval::Embeddings& g, const eval::Embeddings& t,
                           const eval::Embeddings& s, int64_t batch, uint64_t seed) {
  json out;
  for (const char* protocol : {"batches", "all"}) {
    const int64_t b = std::string(protocol) == "batches" ? batch : 0;
    MP_ASSIGN_OR_RETURN(const auto to_target, eval::Retrieval(g, t, b, seed));
    MP_ASSIGN_OR_RETURN(const auto to_source, eval::Retrieval(g, s, b, seed));
    out["generated_to_target"][protocol] = ScoresJson(to_target);
    out["generated_to_source"][protocol] = ScoresJson(to_source);
    out["towards_target"][protocol] = {{"R@1", to_target.r1 - to_source.r1}};
  }
  return out;
}

// params: evaluator (input stage holding the evaluator checkpoint), edits (the edit stage),
// batch (32), seed, method (a name for the report; default: the edit stage's model), yardstick
// ("untrained": this row is the report's untrained editor, initial weights, same sampler),
// jitter_yardsticks (spreads in radians: the copy with that white noise on its joint rotations,
// scored as "jittered_copies").
class EvalEditStage : public StageExecutor {
 public:
  // One task.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    CheckInputParams(plan, path, {"evaluator", "edits"}, errors);
  }
  explicit EvalEditStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "scores edited motions: retrieval against targets and sources, plausibility";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("eval_edit: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    const auto started = std::chrono::steady_clock::now();
    const std::string evaluator_stage = p.value("evaluator", std::string("evaluator"));
    const std::string evaluator = FindCheckpoint(ctx, evaluator_stage);
    if (evaluator.empty())
      return TaskReport::BadInput("eval_edit: input stage '" + evaluator_stage +
                                  "' holds no evaluator checkpoint");
    auto encoder = LoadGenerator(*plugins_, evaluator);
    if (!encoder.ok()) return TaskReport::BadInput(encoder.status().message());
    // The edited motions by triplet id, from every edit task.
    const std::string edits_stage = p.value("edits", std::string());
    std::map<std::string, Motion> edited;
    std::string method = p.value("method", std::string()), edited_checkpoint;
    for (const auto& input : ctx.spec.inputs()) {
      if (!edits_stage.empty() && input.stage() != edits_stage) continue;
      for (const auto& dir : input.dirs()) {
        if (!fs::exists(dir + "/edited.npz")) continue;
        auto clips = ReadClips(dir + "/edited.npz");
        if (!clips.ok()) return TaskReport::BadInput(clips.status().message());
        for (auto& clip : *clips) edited[clip.id] = std::move(clip.motion);
        ReadSummary(dir + "/edits.json", &method, &edited_checkpoint);
      }
    }
    if (edited.size() < 2)
      return TaskReport::BadInput(
          "eval_edit: fewer than 2 edited motions in the inputs (an edit stage)");
    // Their triplets' sources and targets.
    std::vector<Motion> generated, targets, sources;
    std::vector<std::string> ids, edit_texts;
    std::set<std::string> seen;
    for (const std::string& path : TripletFiles(ctx)) {
      auto c = ReadTripletColumns(path, {0, -1, true, false});
      if (!c.ok()) return TaskReport::BadInput(c.status().message());
      for (int64_t r = 0; r < c->rows; ++r) {
        const auto it = edited.find(c->ids[static_cast<size_t>(r)]);
        if (it == edited.end() || !seen.insert(it->first).second) continue;
        ids.push_back(it->first);
        edit_texts.push_back(c->texts.empty() ? std::string() : c->texts[static_cast<size_t>(r)]);
        generated.push_back(it->second);
        targets.push_back(SideMotion(*c, r, false));
        sources.push_back(SideMotion(*c, r, true));
      }
    }
    if (generated.size() != edited.size()) {
      return TaskReport::BadInput("eval_edit: " + std::to_string(edited.size() - generated.size()) +
                                  " edited motion(s) have no triplet in the inputs");
    }
    auto g_rows = (*encoder)->EncodeMotions(generated), t_rows = (*encoder)->EncodeMotions(targets),
         s_rows = (*encoder)->EncodeMotions(sources);
    for (const auto* e : {&g_rows, &t_rows, &s_rows}) {
      if (!e->ok()) return TaskReport::Error("eval_edit: " + e->status().message());
    }
    const auto g = ToEmbeddings(*g_rows), t = ToEmbeddings(*t_rows), s = ToEmbeddings(*s_rows);
    const int64_t batch = p.value("batch", int64_t{32});
    const uint64_t seed = p.value("seed", ctx.spec.seed());
    auto retrieval = EditRetrieval(g, t, s, batch, seed),
         copy = EditRetrieval(s, t, s, batch, seed), target = EditRetrieval(t, t, s, batch, seed);
    auto target_to_source = eval::Retrieval(t, s, batch, seed);
    for (const Status& status :
         {retrieval.status(), copy.status(), target.status(), target_to_source.status()}) {
      if (!status.ok()) return TaskReport::Error("eval_edit: " + status.message());
    }
    json metrics = *retrieval;
    metrics.update({{"method", method},
                    {"evaluator", evaluator},
                    {"motions", generated.size()},
                    {"batch", batch},
                    {"seed", seed}});
    if (p.contains("yardstick"))
      metrics["yardstick"] = p["yardstick"];           // "untrained": the report's untrained row
    if (p.contains("row")) metrics["row"] = p["row"];  // its paper row (configs/papers)
    // The yardsticks, in the same batches (issue 15): the source as the edit (copy: moves nowhere)
    // and the target as the edit (the upper bound).
    metrics["yardsticks"] = {{"copy", *copy}, {"target", *target}};
    metrics["target_to_source"] = {{"batches", ScoresJson(*target_to_source)}};
    metrics["plausibility"] = {{"generated", MeanPlausibility(generated)},
                               {"target", MeanPlausibility(targets)}};
    // Diagnostic (issue 15), on request: the copy with white noise of spread sigma (radians) on
    // every joint rotation, scored in the same batches, shows how much of an edit's score the
    // evaluator loses to roughness alone.
    json jittered = json::object();
    for (double sigma : p.value("jitter_yardsticks", std::vector<double>{})) {
      if (!(sigma > 0 && sigma < 1))
        return TaskReport::BadInput("eval_edit: jitter_yardsticks are spreads in (0, 1) radians");
      std::vector<Motion> noisy = sources;
      Rng rng(seed ^ 0x6a177e12ULL);
      for (Motion& m : noisy) {
        for (float& v : m.poses) v += static_cast<float>(sigma * rng.Normal());
      }
      auto rows = (*encoder)->EncodeMotions(noisy);
      if (!rows.ok()) return TaskReport::Error("eval_edit: " + rows.status().message());
      auto scores = EditRetrieval(ToEmbeddings(*rows), t, s, batch, seed);
      if (!scores.ok()) return TaskReport::Error("eval_edit: " + scores.status().message());
      json entry = *scores;
      entry["sigma"] = sigma;
      entry["plausibility"] = MeanPlausibility(noisy);
      jittered[std::to_string(sigma)] = entry;
    }
    if (!jittered.empty()) metrics["jittered_copies"] = jittered;
    const json& g2t = metrics["generated_to_target"]["all"];
    if (auto failed =
            RecordHistory(ctx, &metrics, method, edited_checkpoint, ids,
                          {{"generated_to_target.all.R@1", g2t["R@1"].get<double>(), true},
                           {"generated_to_target.all.AvgR", g2t["AvgR"].get<double>(), false}})) {
      return *failed;
    }
    if (Status st = WritePreview(
            ctx, {{"source", &sources[0]}, {"edited", &generated[0]}, {"target", &targets[0]}},
            edit_texts[0], ids[0]);
        !st.ok()) {
      return TaskReport::Error("eval_edit: " + st.message());
    }
    AddTiming(&metrics, started, generated.size() * 3);
    TaskReport out = WriteMetrics(ctx, metrics);
    out.metrics["R1_generated_to_target"] =
        metrics["generated_to_target"]["batches"]["R@1"].get<double>();
    out.metrics["AvgR_generated_to_target"] =
        metrics["generated_to_target"]["batches"]["AvgR"].get<double>();
    return out;
  }

 private:
  const PluginHost* plugins_;
};

// The spans table of an input `singles` stage.
Result<sinc::SpanTable> InputSpans(const TaskContext& ctx) {
  for (const auto& input : ctx.spec.inputs()) {
    for (const auto& dir : input.dirs()) {
      if (fs::exists(dir + "/spans.npz")) return sinc::ReadSpans(dir + "/spans.npz");
    }
  }
  return NotFound("no spans.npz in the inputs (a `singles` stage)");
}

// The spans a generation covers: split, kind (pairs | singles | all), limit; in table order.
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

// params: model (the train stage), split (test), spans (pairs | singles | all), limit, compositing
// (single-action checkpoints: the GPT-compositing baseline), samples (generations per text, 1).
class GenerateStage : public StageExecutor {
 public:
  // `shards` tasks (default 2) over the test spans.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    if (!plan.shards_set) plan.shards = 2;
    plan.reduce = false;
    if (plan.inputs.empty())
      errors->push_back(path +
                        ": needs inputs: the train stage of the model and a `singles` stage");
    const auto& p = plan.params;
    if (p.contains("spans") && p["spans"] != "pairs" && p["spans"] != "singles" &&
        p["spans"] != "all") {
      errors->push_back(path + ".params.spans: pairs, singles or all");
    }
    LongLease(plan);
  }
  explicit GenerateStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "generates the test split's action texts with a text-to-motion checkpoint, sharded";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("generate: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    json options = p.value("options", json::object());
    if (p.value("compositing", false)) options["compositing"] = true;
    std::string checkpoint;
    auto generator = OpenModel(ctx, *plugins_, options, &checkpoint);
    if (!generator.ok()) return TaskReport::BadInput("generate: " + generator.status().message());
    auto table = InputSpans(ctx);
    if (!table.ok()) return TaskReport::BadInput("generate: " + table.status().message());
    const auto spans = SelectSpans(*table, p);
    if (spans.empty())
      return TaskReport::BadInput("generate: no spans of that split and kind in the inputs");
    const int samples = std::max(1, p.value("samples", 1));
    std::vector<Clip> clips;
    const auto started = std::chrono::steady_clock::now();
    for (size_t k = static_cast<size_t>(ctx.spec.index()); k < spans.size();
         k += static_cast<size_t>(std::max(1, ctx.spec.count()))) {
      if (ctx.cancelled()) return TaskReport::Error("cancelled");
      const int64_t i = spans[k];
      for (int sample = 0; sample < samples; ++sample) {
        plugin::GenerateRequest r;
        r.texts = {table->text_a[static_cast<size_t>(i)]};
        if (!table->single(i)) r.texts.push_back(table->text_b[static_cast<size_t>(i)]);
        r.frames = table->frames(i);
        r.fps = table->fps[static_cast<size_t>(i)];
        r.seed = MixSeed(ctx.spec.seed(), static_cast<uint64_t>(i * 1000 + sample));
        auto motion = (*generator)->Generate(r);
        if (!motion.ok()) return TaskReport::Error(motion.status().message());
        Clip clip;
        clip.id =
            table->ids[static_cast<size_t>(i)] + (samples > 1 ? "#" + std::to_string(sample) : "");
        clip.source = "generate:" + (*generator)->Name();
        clip.motion = std::move(*motion);
        clip.texts = {SpanText(*table, i)};
        clips.push_back(std::move(clip));
      }
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (!clips.empty()) {
      if (Status st = WriteClips(ctx.output_dir() + "/generated.npz", clips); !st.ok())
        return TaskReport::Error(st.message());
    }
    const json summary = {
        {"model", (*generator)->Name()},
        {"checkpoint", checkpoint},
        {"generated", clips.size()},
        {"seconds", seconds},
        {"motions_per_second", static_cast<double>(clips.size()) / std::max(seconds, 1e-9)}};
    if (Status st = WriteFileAtomic(ctx.output_dir() + "/generate.json", summary.dump(1) + "\n");
        !st.ok())
      return TaskReport::Error(st.message());
    TaskReport out = TaskReport::Ok();
    out.metrics["generated"] = static_cast<double>(clips.size());
    return out;
  }

 private:
  const PluginHost* plugins_;
};

// What eval_generate measures of motions against their ground truth (SINC Tables 2-3), from their
// TEMOS-evaluator features and TMR embeddings: the TEMOS score, APE/AVE, and TMR retrieval
// text-to-generated and generated-to-truth (batches and all).
Result<json> GenerationScores(const std::vector<Motion>& generated,
                              const std::vector<Motion>& truth,
                              const std::vector<std::vector<float>>& g_temos,
                              const std::vector<std::vector<float>>& t_temos,
                              const eval::Embeddings& gen, const eval::Embeddings& gt,
                              const eval::Embeddings& txt, int64_t batch, uint64_t seed) {
  // TEMOS score: mean over the test motions of (1 + cos(f_gt, f_gen)) / 2 (REFERENCE 4.6).
  double temos_score = 0;
  for (size_t i = 0; i < generated.size(); ++i)
    temos_score += (1 + Cosine(g_temos[i], t_temos[i])) / 2;
  const double n = static_cast<double>(generated.size());
  // APE / AVE on joint positions, both motions in their first frame's body frame (REFERENCE 4.5).
  eval::PositionErrors ape, ave;
  for (size_t i = 0; i < generated.size(); ++i) {
    auto gj = ComputeJoints(Skeleton::Smpl22(), generated[i]),
         tj = ComputeJoints(Skeleton::Smpl22(), truth[i]);
    eval::Canonicalize(&gj, kNumJoints, eval::kSmpl22Hips);
    eval::Canonicalize(&tj, kNumJoints, eval::kSmpl22Hips);
    MP_ASSIGN_OR_RETURN(const auto a,
                        eval::AveragePositionalError(gj, tj, kNumJoints, eval::kSmpl22Hips));
    MP_ASSIGN_OR_RETURN(const auto v,
                        eval::AverageVarianceError(gj, tj, kNumJoints, eval::kSmpl22Hips));
    ape.root += a.root, ape.trajectory += a.trajectory, ape.mean_local += a.mean_local,
        ape.mean_global += a.mean_global;
    ave.root += v.root, ave.trajectory += v.trajectory, ave.mean_local += v.mean_local,
        ave.mean_global += v.mean_global;
  }
  const auto errors_json = [n](const eval::PositionErrors& e) {
    return json{{"root", e.root / n},
                {"trajectory", e.trajectory / n},
                {"mean_local", e.mean_local / n},
                {"mean_global", e.mean_global / n}};
  };
  json out = {
      {"temos_score", temos_score / n}, {"APE", errors_json(ape)}, {"AVE", errors_json(ave)}};
  for (const auto& [key, queries, gallery] :
       {std::tuple{"text_to_generated", &txt, &gen}, std::tuple{"generated_to_truth", &gen, &gt}}) {
    MP_ASSIGN_OR_RETURN(const auto batches, eval::Retrieval(*queries, *gallery, batch, seed));
    MP_ASSIGN_OR_RETURN(const auto all, eval::Retrieval(*queries, *gallery, 0, seed));
    out[key] = {{"batches", ScoresJson(batches)}, {"all", ScoresJson(all)}};
  }
  return out;
}

// For each motion, another one of the nearest length (its neighbour in length order): the shuffled
// ground truth yardstick, a real motion of the same length class for the wrong text.
std::vector<size_t> SameLengthClassPartner(const std::vector<Motion>& motions) {
  std::vector<size_t> order(motions.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return motions[a].num_frames() < motions[b].num_frames();
  });
  std::vector<size_t> partner(motions.size());
  for (size_t k = 0; k < order.size(); ++k)
    partner[order[k]] = order[k + 1 < order.size() ? k + 1 : k - 1];
  return partner;
}

// The TMR evaluator's own retrieval on the held-out test split (issue 15): text-to-motion and
// motion-to-text R@1/R@3 in batches, on single actions and on two-action spans ("A while B").
Result<json> EvaluatorQuality(plugin::Generator& tmr, const sinc::SpanTable& table, int64_t batch,
                              uint64_t seed) {
  json out;
  for (const char* kind : {"singles", "pairs"}) {
    const auto spans = SelectSpans(table, {{"split", "test"}, {"spans", kind}});
    if (spans.size() < 2) continue;
    std::vector<Motion> motions;
    std::vector<std::string> texts;
    for (const int64_t i : spans)
      motions.push_back(table.MotionOf(i)), texts.push_back(SpanText(table, i));
    MP_ASSIGN_OR_RETURN(auto m_rows, tmr.EncodeMotions(motions));
    MP_ASSIGN_OR_RETURN(auto t_rows, tmr.EncodeTexts(texts));
    const auto m = ToEmbeddings(m_rows), t = ToEmbeddings(t_rows);
    const int64_t b = std::min<int64_t>(batch, static_cast<int64_t>(spans.size()));
    MP_ASSIGN_OR_RETURN(const auto text_to_motion, eval::Retrieval(t, m, b, seed));
    MP_ASSIGN_OR_RETURN(const auto motion_to_text, eval::Retrieval(m, t, b, seed));
    out[kind] = {{"motions", spans.size()},
                 {"text_to_motion", ScoresJson(text_to_motion)},
                 {"motion_to_text", ScoresJson(motion_to_text)}};
  }
  return out;
}

// params: evaluator (TMR: retrieval), temos (TEMOS on real singles: the TEMOS score; default the
// evaluator), generated (the generate stage), batch (32), seed, diversity_pairs (300), method.
// yardstick ("untrained": the report's untrained generator), evaluator_quality (true: also the
// TMR's own retrieval on the test singles and two-action spans).
class EvalGenerateStage : public StageExecutor {
 public:
  // One task.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    CheckInputParams(plan, path, {"evaluator", "temos", "generated"}, errors);
  }
  explicit EvalGenerateStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "scores generated motions against the ground truth: TEMOS score, APE/AVE, retrieval";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("eval_generate: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    const auto started = std::chrono::steady_clock::now();
    const auto load = [&](const std::string& stage) -> Result<GeneratorPtr> {
      const std::string dir = FindCheckpoint(ctx, stage);
      if (dir.empty()) return NotFound("input stage '" + stage + "' holds no checkpoint");
      return LoadGenerator(*plugins_, dir);
    };
    auto tmr = load(p.value("evaluator", std::string("evaluator")));
    if (!tmr.ok()) return TaskReport::BadInput("eval_generate: " + tmr.status().message());
    const std::string temos_stage = p.value("temos", std::string());
    Result<GeneratorPtr> temos =
        temos_stage.empty() ? Result<GeneratorPtr>(NotFound("")) : load(temos_stage);
    if (!temos_stage.empty() && !temos.ok())
      return TaskReport::BadInput("eval_generate: " + temos.status().message());
    plugin::Generator& temos_encoder = temos_stage.empty() ? **tmr : **temos;
    auto table = InputSpans(ctx);
    if (!table.ok()) return TaskReport::BadInput("eval_generate: " + table.status().message());
    std::map<std::string, int64_t> span_of;
    for (int64_t i = 0; i < table->size(); ++i) span_of[table->ids[static_cast<size_t>(i)]] = i;
    // The generated motions (first sample of each span) and their ground truth.
    const std::string generated_stage = p.value("generated", std::string());
    std::vector<Motion> generated, truth;
    std::vector<std::string> texts, ids;
    std::string method = p.value("method", std::string()), generated_checkpoint;
    for (const auto& input : ctx.spec.inputs()) {
      if (!generated_stage.empty() && input.stage() != generated_stage) continue;
      for (const auto& dir : input.dirs()) {
        if (!fs::exists(dir + "/generated.npz")) continue;
        auto clips = ReadClips(dir + "/generated.npz");
        if (!clips.ok()) return TaskReport::BadInput(clips.status().message());
        for (auto& clip : *clips) {
          const auto it = span_of.find(clip.id);
          if (it == span_of.end()) continue;  // extra samples ("id#k") and unknown ids
          ids.push_back(clip.id);
          texts.push_back(clip.texts.empty() ? std::string() : clip.texts[0]);
          generated.push_back(std::move(clip.motion));
          truth.push_back(table->MotionOf(it->second));
        }
        ReadSummary(dir + "/generate.json", &method, &generated_checkpoint);
      }
    }
    if (generated.size() < 2)
      return TaskReport::BadInput(
          "eval_generate: fewer than 2 generated motions with a ground truth in the inputs");
    auto g_tmr = (*tmr)->EncodeMotions(generated), t_tmr = (*tmr)->EncodeMotions(truth),
         text_tmr = (*tmr)->EncodeTexts(texts);
    auto g_temos = temos_encoder.EncodeMotions(generated),
         t_temos = temos_encoder.EncodeMotions(truth);
    for (const auto* r : {&g_tmr, &t_tmr, &text_tmr, &g_temos, &t_temos}) {
      if (!r->ok()) return TaskReport::Error("eval_generate: " + r->status().message());
    }
    const int64_t batch = p.value("batch", int64_t{32});
    const uint64_t seed = p.value("seed", ctx.spec.seed());
    const auto gen = ToEmbeddings(*g_tmr), gt = ToEmbeddings(*t_tmr), txt = ToEmbeddings(*text_tmr);
    auto scores = GenerationScores(generated, truth, *g_temos, *t_temos, gen, gt, txt, batch, seed);
    if (!scores.ok()) return TaskReport::Error("eval_generate: " + scores.status().message());
    json metrics = *std::move(scores);
    metrics.update(
        {{"method", method}, {"motions", generated.size()}, {"batch", batch}, {"seed", seed}});
    if (p.contains("yardstick"))
      metrics["yardstick"] = p["yardstick"];           // "untrained": the report's untrained row
    if (p.contains("row")) metrics["row"] = p["row"];  // its paper row (configs/papers)
    // The yardsticks, in the same evaluation (issue 15): the ground truth itself, and shuffled
    // ground truth (each test motion stands in for the one nearest in length to it).
    const std::vector<size_t> other = SameLengthClassPartner(truth);
    std::vector<Motion> shuffled;
    std::vector<std::vector<float>> shuffled_temos, shuffled_tmr;
    for (size_t i = 0; i < truth.size(); ++i) {
      shuffled.push_back(truth[other[i]]);
      shuffled_temos.push_back((*t_temos)[other[i]]);
      shuffled_tmr.push_back((*t_tmr)[other[i]]);
    }
    auto truth_scores =
        GenerationScores(truth, truth, *t_temos, *t_temos, gt, gt, txt, batch, seed);
    auto shuffled_scores = GenerationScores(shuffled, truth, shuffled_temos, *t_temos,
                                            ToEmbeddings(shuffled_tmr), gt, txt, batch, seed);
    if (!truth_scores.ok() || !shuffled_scores.ok()) {
      return TaskReport::Error(
          "eval_generate: " +
          (truth_scores.ok() ? shuffled_scores.status() : truth_scores.status()).message());
    }
    metrics["yardsticks"] = {{"truth", *truth_scores}, {"shuffled", *shuffled_scores}};
    if (p.value("evaluator_quality", false)) {
      auto quality = EvaluatorQuality(**tmr, *table, batch, seed);
      if (!quality.ok()) return TaskReport::Error("eval_generate: " + quality.status().message());
      metrics["evaluator_quality"] = *quality;
    }
    const double temos_score = metrics["temos_score"].get<double>();
    const int64_t pairs = p.value("diversity_pairs", int64_t{300});
    metrics["diversity"] = {{"generated", eval::Diversity(gen, pairs, seed)},
                            {"truth", eval::Diversity(gt, pairs, seed)}};
    metrics["fid"] = nullptr;  // needs more motions than dimensions
    if (gen.n > gen.d) {
      auto fid = eval::FrechetDistance(gt, gen);
      if (!fid.ok()) return TaskReport::Error("eval_generate: " + fid.status().message());
      metrics["fid"] = *fid;
    }
    metrics["plausibility"] = {{"generated", MeanPlausibility(generated)},
                               {"truth", MeanPlausibility(truth)}};
    if (auto failed =
            RecordHistory(ctx, &metrics, method, generated_checkpoint, ids,
                          {{"temos_score", temos_score, true},
                           {"APE.mean_global", metrics["APE"]["mean_global"].get<double>(), false},
                           {"text_to_generated.all.R@1",
                            metrics["text_to_generated"]["all"]["R@1"].get<double>(), true}})) {
      return *failed;
    }
    if (Status st = WritePreview(ctx, {{"generated", &generated[0]}, {"truth", &truth[0]}},
                                 texts[0], ids[0]);
        !st.ok()) {
      return TaskReport::Error("eval_generate: " + st.message());
    }
    AddTiming(&metrics, started, generated.size() * 2);
    TaskReport out = WriteMetrics(ctx, metrics);
    out.metrics["temos_score"] = temos_score;
    return out;
  }

 private:
  const PluginHost* plugins_;
};

}  // namespace

// The real CMU clips through the trained system, for the report: each clip imported (BVH, 120 fps,
// 31 joints -> SMPL-22 at 30 fps); the first clip composed with a corpus action by body parts
// (SINC sec. 3.1: the clip keeps legs, trajectory and torso, the corpus action brings its arm) and
// the composition's text generated by the SINC model; the first clip edited by the MDT editor; the
// plausibility of every motion and the TMR evaluator's cosine similarity to the CMU source; GIFs.
// params: clips (BVH files or a directory; default data/mocap/cmu), max_frames (150), editor,
// generator, evaluator (input stages with the checkpoints), edit_text, clip_text (the first clip's
// action, labelled for its body parts), partner_text (the corpus action to compose with; default:
// the first test single moving only the arms), steps (DDIM, 50), panel_size (200). Outputs:
// showcase.json (read by the report), *.gif, cmu.npz (the imported clips), composed.npz,
// edited.npz.
class ShowcaseStage : public StageExecutor {
 public:
  // One task.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    CheckInputParams(plan, path, {"editor", "generator", "evaluator"}, errors);
    // What the showcase shows is the pipeline's choice, not the engine's.
    for (const char* key : {"clips", "clip_text", "edit_text"}) {
      if (!plan.params.contains(key))
        errors->push_back(path + ".params." + key +
                          ": required (the clips to import, the first clip's action text, the edit "
                          "instruction)");
    }
  }
  explicit ShowcaseStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "real clips through import, body-part composition, generation, editing, metrics and "
           "rendering";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("showcase: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    const std::string out = ctx.output_dir();
    // 1. Import.
    const int64_t max_frames = p.value("max_frames", int64_t{150});
    auto imported = ImportClips(p.at("clips"), max_frames);
    if (!imported.ok()) return TaskReport::FromStatus(imported.status());
    const std::vector<Clip>& cmu = *imported;
    if (Status st = WriteClips(out + "/cmu.npz", cmu); !st.ok())
      return TaskReport::Error(st.message());
    const Motion& source = cmu.front().motion;
    const std::string clip_text = p.at("clip_text").get<std::string>();
    const std::string edit_text = p.at("edit_text").get<std::string>();
    // Panel and row labels: the clips' (params.clips_label, default "clip"), the generator's and
    // the editor's (default: their stage names).
    const std::string clips_label = p.value("clips_label", std::string("clip"));
    const std::string generator_label =
        p.value("generator_label", p.value("generator", std::string("generator")));
    const std::string editor_label =
        p.value("editor_label", p.value("editor", std::string("editor")));
    const std::string first = clips_label + " " + cmu.front().id;
    const auto load = [&](const char* key) -> Result<GeneratorPtr> {
      const std::string stage = p.value(key, std::string(key));
      const std::string dir = FindCheckpoint(ctx, stage);
      if (dir.empty())
        return NotFound(std::string("showcase: params.") + key + ": input stage '" + stage +
                        "' holds no checkpoint");
      return LoadGenerator(*plugins_, dir);
    };
    auto evaluator = load("evaluator");
    auto editor = load("editor");
    auto generator = load("generator");
    for (const auto* g : {&evaluator, &editor, &generator}) {
      if (!g->ok()) return TaskReport::BadInput(g->status().message());
    }
    // 2. Composition with a corpus action whose parts are disjoint from the clip's (test split,
    // arms).
    auto table = InputSpans(ctx);
    if (!table.ok()) return TaskReport::BadInput("showcase: " + table.status().message());
    const PartSet clip_parts = labels::LexiconParts(clip_text);
    const int64_t partner = PickPartner(*table, clip_parts, p.value("partner_text", std::string()));
    if (partner < 0)
      return TaskReport::BadInput(
          "showcase: no test single in the spans table is compatible with '" + clip_text + "'");
    const Motion corpus_motion = table->MotionOf(partner);
    const std::string partner_text = table->text_a[static_cast<size_t>(partner)];
    const PartSet partner_parts = table->parts_a[static_cast<size_t>(partner)];
    const Motion composed =
        sinc::Compose(source, clip_parts, corpus_motion, partner_parts, sinc::CropMode::kFirst);
    const std::string pair_text = sinc::EvalPairText(clip_text, partner_text);
    // 3. The generator's own motion for the pair's text, and the editor's edit of the clip.
    plugin::GenerateRequest gen_request;
    gen_request.texts = {pair_text};
    gen_request.frames = composed.num_frames();
    gen_request.seed = ctx.spec.seed();
    auto generated = (*generator)->Generate(gen_request);
    if (!generated.ok())
      return TaskReport::Error("showcase: generation: " + generated.status().message());
    plugin::GenerateRequest edit_request;
    edit_request.texts = {edit_text};
    edit_request.source = &source;
    edit_request.seed = ctx.spec.seed();
    edit_request.sampler = "ddim";
    edit_request.steps = static_cast<int>(p.value("steps", int64_t{50}));
    auto edited = (*editor)->Generate(edit_request);
    if (!edited.ok()) return TaskReport::Error("showcase: editing: " + edited.status().message());
    using Output = std::tuple<std::string, const Motion*, std::string>;
    for (const auto& [name, motion, text] : {Output{"composed.npz", &composed, pair_text},
                                             Output{"generated.npz", &*generated, pair_text},
                                             Output{"edited.npz", &*edited, edit_text}}) {
      Clip clip;
      clip.id = fs::path(name).stem().string();
      clip.source = cmu.front().source;
      clip.motion = *motion;
      clip.texts = {text};
      if (Status st = WriteClips(out + "/" + name, {clip}); !st.ok())
        return TaskReport::Error(st.message());
    }
    // 4. Metrics: plausibility, and the evaluator's cosine similarity to the first clip.
    std::vector<std::pair<std::string, const Motion*>> rows = {};
    for (const Clip& c : cmu) rows.push_back({clips_label + " " + c.id + " (imported)", &c.motion});
    rows.push_back({"corpus: " + partner_text, &corpus_motion});
    rows.push_back({"composition: " + pair_text, &composed});
    rows.push_back({generator_label + " generated: " + pair_text, &*generated});
    rows.push_back({editor_label + " edit: " + edit_text, &*edited});
    std::vector<Motion> motions;
    for (const auto& r : rows) motions.push_back(*r.second);
    auto embeddings = (*evaluator)->EncodeMotions(motions);
    if (!embeddings.ok()) return TaskReport::Error("showcase: " + embeddings.status().message());
    json table_rows = json::array();
    for (size_t i = 0; i < rows.size(); ++i) {
      const auto r = EvaluateMotionPlausibility(Skeleton::Smpl22(), *rows[i].second);
      table_rows.push_back({rows[i].first, rows[i].second->num_frames(), r.foot_skate_ratio,
                            r.penetration_mean, r.float_ratio, r.jerk_mean,
                            Cosine((*embeddings)[i], (*embeddings)[0])});
    }
    // 5. Renders.
    render::RenderOptions options;
    options.panel_width = options.panel_height =
        static_cast<int>(p.value("panel_size", int64_t{200}));
    options.fps = 10;
    std::vector<render::MotionPanel> import_panels;
    for (const Clip& c : cmu)
      import_panels.push_back({c.motion, clips_label + " " + c.id, c.source});
    const std::vector<std::pair<std::string, std::vector<render::MotionPanel>>> gifs = {
        {"cmu_import.gif", import_panels},
        {"cmu_composition.gif",
         {{source, first, clip_text},
          {corpus_motion, "corpus", partner_text},
          {composed, "composition", pair_text},
          {*generated, generator_label, pair_text}}},
        {"cmu_edit.gif",
         {{source, first, "source"}, {*edited, editor_label + " edit", edit_text}}}};
    for (const auto& [name, panels] : gifs) {
      if (Status st = render::RenderMotionFile(out + "/" + name, panels, options); !st.ok())
        return TaskReport::Error(st.message());
    }
    const json showcase = {
        {"title", "Real data: the " + clips_label + " clips through the system"},
        {"text", "The " + clips_label + " clips imported onto SMPL-22 at 30 fps and cut to " +
                     std::to_string(max_frames) + " frames; " + cmu.front().id + " (\"" +
                     clip_text + "\", parts " + PartSetToString(clip_parts) +
                     ") composed by body parts with the corpus's test action \"" + partner_text +
                     "\" (parts " + PartSetToString(partner_parts) + "), next to the " +
                     generator_label +
                     " model's own motion for the pair's text; and edited by the " + editor_label +
                     " with \"" + edit_text + "\" (DDIM " + std::to_string(edit_request.steps) +
                     " steps)."},
        {"items",
         {{{"image", "cmu_import.gif"}, {"caption", "The imported " + clips_label + " clips"}},
          {{"image", "cmu_composition.gif"},
           {"caption", "Composition by body parts: " + pair_text}},
          {{"image", "cmu_edit.gif"},
           {"caption", editor_label + " edit of " + cmu.front().id + ": " + edit_text}}}},
        {"table",
         {{"caption",
           "Plausibility of the real, composed, generated and edited motions, and the "
           "evaluator's cosine similarity to " +
               first},
          {"columns",
           {"motion", "frames", "foot skate", "penetration (m)", "floating", "jerk",
            "cos to " + cmu.front().id}},
          {"rows", table_rows}}}};
    if (Status st = WriteFileAtomic(layout::ShowcaseFile(out), showcase.dump(1) + "\n"); !st.ok())
      return TaskReport::Error(st.message());
    return TaskReport::Ok();
  }

 private:
  // The BVH files of `clips` (files or directories), sorted, imported onto SMPL-22 at 30 fps and
  // cut to max_frames (the models' training length).
  static Result<std::vector<Clip>> ImportClips(const json& clips, int64_t max_frames) {
    std::vector<std::string> files;
    const auto add = [&](const std::string& path) {
      if (fs::is_directory(path)) {
        for (const auto& e : fs::directory_iterator(path)) {
          if (e.path().extension() == ".bvh") files.push_back(e.path().string());
        }
      } else {
        files.push_back(path);
      }
    };
    if (clips.is_array()) {
      for (const json& c : clips) add(c.get<std::string>());
    } else {
      add(clips.get<std::string>());
    }
    std::sort(files.begin(), files.end());
    if (files.empty()) return InvalidArgument("showcase: no BVH files in " + clips.dump());
    std::vector<Clip> cmu;
    for (const std::string& f : files) {
      auto loaded = LoadMotionFile(f, 30);
      if (!loaded.ok()) return InvalidArgument("showcase: " + loaded.status().message());
      Clip clip = std::move(loaded->front());
      clip.id = fs::path(f).stem().string();
      clip.source = "cmu:" + fs::path(f).filename().string();
      if (clip.motion.num_frames() > max_frames) {
        clip.motion.poses.resize(static_cast<size_t>(max_frames) * kNumJoints * 3);
        clip.motion.trans.resize(static_cast<size_t>(max_frames) * 3);
      }
      clip.joints.clear();
      clip.segments.clear();
      cmu.push_back(std::move(clip));
    }
    return cmu;
  }

  // The corpus action to compose the clip with (SINC sec. 3.1): the test single `wanted` if given,
  // else the first test single that moves only the arms (what SINC composes with a walk), else the
  // first compatible one; -1 when none is.
  static int64_t PickPartner(const sinc::SpanTable& table, PartSet clip_parts,
                             const std::string& wanted) {
    const PartSet arms =
        static_cast<PartSet>(PartBit(BodyPart::kLeftArm) | PartBit(BodyPart::kRightArm));
    int64_t partner = -1, fallback = -1;
    for (int64_t i = 0; i < table.size() && partner < 0; ++i) {
      if (!table.single(i) || table.splits[static_cast<size_t>(i)] != "test" ||
          table.frames(i) < 30)
        continue;
      const PartSet parts = table.parts_a[static_cast<size_t>(i)];
      if (!sinc::Compatible(clip_parts, parts)) continue;
      if (!wanted.empty()) {
        if (table.text_a[static_cast<size_t>(i)] == wanted) partner = i;
      } else if ((parts & ~arms) == 0) {
        partner = i;
      } else if (fallback < 0) {
        fallback = i;
      }
    }
    return partner < 0 && wanted.empty() ? fallback : partner;
  }

  const PluginHost* plugins_;
};

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
                      {"edit_methods", summary->edit_methods},
                      {"generation_methods", summary->generation_methods}};
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

void RegisterModelExecutors(ExecutorRegistry* registry, const PluginHost* plugins) {
  registry->Register("edit", std::make_unique<EditStage>(plugins));
  registry->Register("eval_edit", std::make_unique<EvalEditStage>(plugins));
  registry->Register("generate", std::make_unique<GenerateStage>(plugins));
  registry->Register("eval_generate", std::make_unique<EvalGenerateStage>(plugins));
  registry->Register("report", std::make_unique<ReportStage>());
  registry->Register("showcase", std::make_unique<ShowcaseStage>(plugins));
}

}  // namespace motionpipe::worker
