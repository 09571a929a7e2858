// `eval_edit`: scores an edit stage's motions with an evaluator checkpoint: motion-to-motion
// retrieval generated-to-target and generated-to-source (SimMotionEdit Table 1), beside the
// yardsticks, and the physical plausibility of the edits and of the targets.
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>

#include "evaluation.h"
#include "inputs.h"
#include "motionpipe/base/random.h"
#include "motionpipe/eval/metrics.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// Retrieval of edits `g` among the targets and among the sources (batches and all), and how far the
// edits move towards their targets: generated-to-target minus generated-to-source R@1 (the copy of
// the source scores about -(target-to-source R@1), the target itself about +that), with its
// standard error over the edits (paired per edit: one evaluation's sampling error; seeds add
// theirs).
Result<json> EditRetrieval(const eval::Embeddings& g, const eval::Embeddings& t,
                           const eval::Embeddings& s, int64_t batch, uint64_t seed) {
  json out;
  for (const char* protocol : {"batches", "all"}) {
    const int64_t b = std::string(protocol) == "batches" ? batch : 0;
    MP_ASSIGN_OR_RETURN(const auto to_target, eval::Retrieval(g, t, b, seed));
    MP_ASSIGN_OR_RETURN(const auto to_source, eval::Retrieval(g, s, b, seed));
    out["generated_to_target"][protocol] = ScoresJson(to_target);
    out["generated_to_source"][protocol] = ScoresJson(to_source);
    const eval::PairedDifference towards = eval::PairedR1Difference(to_target, to_source);
    out["towards_target"][protocol] = {{"R@1", towards.value}, {"se", towards.standard_error}};
  }
  return out;
}

// Per edit, in the evaluator's space (issue 15): whether the edit `g` lies closer to its target
// than to its source by cosine similarity, overall and by the triplet's edit kind (the corpus's
// `kinds` column: speed, posture, ...; absent for MotionFix). A copy of the source scores 0, the
// target itself 1: unlike batch retrieval, this says which edits move the right way.
json CloserToTarget(const std::vector<std::vector<float>>& g,
                    const std::vector<std::vector<float>>& t,
                    const std::vector<std::vector<float>>& s,
                    const std::vector<std::string>& kinds) {
  struct Sum {
    int64_t n = 0, closer = 0;
    double to_target = 0, to_source = 0;
    json Json() const {
      const double d = static_cast<double>(std::max<int64_t>(1, n));
      const double fraction = static_cast<double>(closer) / d;
      return {{"triplets", n},
              {"fraction", fraction},
              {"fraction_se", std::sqrt(fraction * (1 - fraction) / d)},  // binomial
              {"cos_to_target", to_target / d},
              {"cos_to_source", to_source / d}};
    }
  };
  Sum all;
  std::map<std::string, Sum> by_kind;
  for (size_t i = 0; i < g.size(); ++i) {
    const double ct = Cosine(g[i], t[i]), cs = Cosine(g[i], s[i]);
    for (Sum* sum : {&all, kinds[i].empty() ? nullptr : &by_kind[kinds[i]]}) {
      if (!sum) continue;
      ++sum->n, sum->closer += ct > cs ? 1 : 0, sum->to_target += ct, sum->to_source += cs;
    }
  }
  json out = all.Json();
  for (const auto& [kind, sum] : by_kind) out["by_edit_kind"][kind] = sum.Json();
  return out;
}

// params: evaluator (input stage holding the evaluator checkpoint), edits (the edit stage),
// triplets (the stage holding the triplets; default: every input); evaluator, edits and triplets
// may also be path patterns (an earlier job's stage: rescoring without editing again),
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
    CheckInputParams(plan, path, {"evaluator", "edits", "triplets"}, errors);
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
    for (const std::string& dir : StageDirs(ctx, edits_stage)) {
      if (!fs::exists(dir + "/edited.npz")) continue;
      auto clips = ReadClips(dir + "/edited.npz");
      if (!clips.ok()) return TaskReport::BadInput(clips.status().message());
      for (auto& clip : *clips) edited[clip.id] = std::move(clip.motion);
      ReadSummary(dir + "/edits.json", &method, &edited_checkpoint);
    }
    if (edited.size() < 2)
      return TaskReport::BadInput(
          "eval_edit: fewer than 2 edited motions in the inputs (an edit stage)");
    // Their triplets' sources and targets.
    std::vector<Motion> generated, targets, sources;
    std::vector<std::string> ids, edit_texts, edit_kinds;
    std::set<std::string> seen;
    for (const std::string& path : TripletFiles(ctx, p.value("triplets", std::string()))) {
      auto c = ReadTripletColumns(path, {0, -1, true, false});
      if (!c.ok()) return TaskReport::BadInput(c.status().message());
      for (int64_t r = 0; r < c->rows; ++r) {
        const auto it = edited.find(c->ids[static_cast<size_t>(r)]);
        if (it == edited.end() || !seen.insert(it->first).second) continue;
        ids.push_back(it->first);
        edit_texts.push_back(c->texts.empty() ? std::string() : c->texts[static_cast<size_t>(r)]);
        edit_kinds.push_back(c->kinds.empty() ? std::string() : c->kinds[static_cast<size_t>(r)]);
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
    // Another triplet's target as the edit (each takes the one half the list away): a motion of
    // the corpus unrelated to both, the chance level of every measure.
    std::vector<std::vector<float>> other_rows(t_rows->size());
    for (size_t i = 0; i < other_rows.size(); ++i)
      other_rows[i] = (*t_rows)[(i + other_rows.size() / 2) % other_rows.size()];
    const auto other = ToEmbeddings(other_rows);
    auto retrieval = EditRetrieval(g, t, s, batch, seed),
         copy = EditRetrieval(s, t, s, batch, seed), target = EditRetrieval(t, t, s, batch, seed),
         unrelated = EditRetrieval(other, t, s, batch, seed);
    auto target_to_source = eval::Retrieval(t, s, batch, seed);
    for (const Status& status : {retrieval.status(), copy.status(), target.status(),
                                 unrelated.status(), target_to_source.status()}) {
      if (!status.ok()) return TaskReport::Error("eval_edit: " + status.message());
    }
    json metrics = *retrieval;
    metrics.update({{"evaluation", "edit"},  // its layout: configs/evaluations/edit.yaml
                    {"method", method},
                    {"evaluator", evaluator},
                    {"motions", generated.size()},
                    {"batch", batch},
                    {"seed", seed}});
    if (p.contains("yardstick"))
      metrics["yardstick"] = p["yardstick"];           // "untrained": the report's untrained row
    if (p.contains("row")) metrics["row"] = p["row"];  // its paper row (configs/papers)
    // The yardsticks, in the same batches (issue 15): the source as the edit (copy: moves nowhere),
    // the target as the edit (the upper bound) and another triplet's target (chance).
    metrics["yardsticks"] = {{"copy", *copy}, {"target", *target}, {"other_target", *unrelated}};
    metrics["closer_to_target"] = CloserToTarget(*g_rows, *t_rows, *s_rows, edit_kinds);
    metrics["yardsticks"]["copy"]["closer_to_target"] =
        CloserToTarget(*s_rows, *t_rows, *s_rows, edit_kinds);
    metrics["yardsticks"]["target"]["closer_to_target"] =
        CloserToTarget(*t_rows, *t_rows, *s_rows, edit_kinds);
    metrics["yardsticks"]["other_target"]["closer_to_target"] =
        CloserToTarget(other_rows, *t_rows, *s_rows, edit_kinds);
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

}  // namespace

MP_STAGE_KIND("eval_edit", EvalEditStage);

}  // namespace motionpipe::stages
