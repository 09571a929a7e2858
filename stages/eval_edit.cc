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

// The edits, their triplets' sources and targets, and what the scores need besides.
struct EditSet {
  std::vector<Motion> generated, targets, sources;
  std::vector<std::string> edit_kinds;
  int64_t batch = 32;
  uint64_t seed = 0;
  std::vector<double> jitter_sigmas;
};

// Everything eval_edit reports that depends on the evaluator: retrieval of the edits and of the
// yardsticks in the same batches (issue 15: the source as the edit (copy: moves nowhere), the
// target as the edit (the upper bound) and another triplet's target (chance)), which edits lie
// closer to their targets, target-to-source retrieval, and on request the jittered copies.
Result<json> ScoreWith(plugin::Generator& encoder, const EditSet& e) {
  MP_ASSIGN_OR_RETURN(const auto g_rows, encoder.EncodeMotions(e.generated));
  MP_ASSIGN_OR_RETURN(const auto t_rows, encoder.EncodeMotions(e.targets));
  MP_ASSIGN_OR_RETURN(const auto s_rows, encoder.EncodeMotions(e.sources));
  const auto g = ToEmbeddings(g_rows), t = ToEmbeddings(t_rows), s = ToEmbeddings(s_rows);
  // Another triplet's target as the edit (each takes the one half the list away): a motion of
  // the corpus unrelated to both, the chance level of every measure.
  std::vector<std::vector<float>> other_rows(t_rows.size());
  for (size_t i = 0; i < other_rows.size(); ++i)
    other_rows[i] = t_rows[(i + other_rows.size() / 2) % other_rows.size()];
  const auto other = ToEmbeddings(other_rows);
  MP_ASSIGN_OR_RETURN(json metrics, EditRetrieval(g, t, s, e.batch, e.seed));
  MP_ASSIGN_OR_RETURN(const json copy, EditRetrieval(s, t, s, e.batch, e.seed));
  MP_ASSIGN_OR_RETURN(const json target, EditRetrieval(t, t, s, e.batch, e.seed));
  MP_ASSIGN_OR_RETURN(const json unrelated, EditRetrieval(other, t, s, e.batch, e.seed));
  MP_ASSIGN_OR_RETURN(const auto target_to_source, eval::Retrieval(t, s, e.batch, e.seed));
  metrics["yardsticks"] = {{"copy", copy}, {"target", target}, {"other_target", unrelated}};
  metrics["closer_to_target"] = CloserToTarget(g_rows, t_rows, s_rows, e.edit_kinds);
  metrics["yardsticks"]["copy"]["closer_to_target"] =
      CloserToTarget(s_rows, t_rows, s_rows, e.edit_kinds);
  metrics["yardsticks"]["target"]["closer_to_target"] =
      CloserToTarget(t_rows, t_rows, s_rows, e.edit_kinds);
  metrics["yardsticks"]["other_target"]["closer_to_target"] =
      CloserToTarget(other_rows, t_rows, s_rows, e.edit_kinds);
  metrics["target_to_source"] = {{"batches", ScoresJson(target_to_source)}};
  // Diagnostic (issue 15), on request: the copy with white noise of spread sigma (radians) on
  // every joint rotation, scored in the same batches, shows how much of an edit's score the
  // evaluator loses to roughness alone.
  json jittered = json::object();
  for (double sigma : e.jitter_sigmas) {
    std::vector<Motion> noisy = e.sources;
    Rng rng(e.seed ^ 0x6a177e12ULL);
    for (Motion& m : noisy) {
      for (float& v : m.poses) v += static_cast<float>(sigma * rng.Normal());
    }
    MP_ASSIGN_OR_RETURN(const auto rows, encoder.EncodeMotions(noisy));
    MP_ASSIGN_OR_RETURN(json entry, EditRetrieval(ToEmbeddings(rows), t, s, e.batch, e.seed));
    entry["sigma"] = sigma;
    entry["plausibility"] = MeanPlausibility(noisy);
    jittered[std::to_string(sigma)] = entry;
  }
  if (!jittered.empty()) metrics["jittered_copies"] = jittered;
  return metrics;
}

// The mean of several evaluators' scores, leaf by leaf: numbers averaged, objects and equally long
// arrays recursed into, anything else (a string) taken from the first.
json MeanOf(const std::vector<json>& each) {
  const json& first = each.front();
  if (first.is_number()) {
    double sum = 0;
    bool equal = true;  // counts (queries, triplets) stay as they are
    for (const json& j : each) {
      if (!j.is_number()) return first;
      sum += j.get<double>();
      equal = equal && j == first;
    }
    if (equal) return first;
    return sum / static_cast<double>(each.size());
  }
  const auto gather = [&](const auto& at) {
    std::vector<json> parts;
    for (const json& j : each) parts.push_back(at(j));
    return MeanOf(parts);
  };
  if (first.is_object()) {
    json out = json::object();
    for (const auto& [key, value] : first.items()) {
      bool everywhere = true;
      for (const json& j : each) everywhere = everywhere && j.is_object() && j.contains(key);
      out[key] = everywhere ? gather([&](const json& j) { return j.at(key); }) : value;
    }
    return out;
  }
  if (first.is_array()) {
    for (const json& j : each) {
      if (!j.is_array() || j.size() != first.size()) return first;
    }
    json out = json::array();
    for (size_t i = 0; i < first.size(); ++i)
      out.push_back(gather([&](const json& j) { return j.at(i); }));
    return out;
  }
  return first;
}

// params: evaluator (input stage holding the evaluator checkpoint, or a list of them: every score
// is then the mean over the evaluators, and by_evaluator lists each one's headline figures), edits
// (the edit stage),
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
    CheckInputParams(plan, path, {"edits", "triplets"}, errors);
    CheckInputListParams(plan, path, {"evaluator"}, errors);
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
    // One evaluator (a name) or several (a list): their scores are averaged.
    std::vector<std::string> evaluator_names;
    const json& named = p.contains("evaluator") ? p["evaluator"] : json("evaluator");
    for (const json& name : named.is_array() ? named : json::array({named})) {
      if (!name.is_string())
        return TaskReport::BadInput(
            "eval_edit: params.evaluator must be a name or a list of names");
      evaluator_names.push_back(name.get<std::string>());
    }
    if (evaluator_names.empty())
      return TaskReport::BadInput("eval_edit: params.evaluator names no evaluator");
    std::vector<std::string> checkpoints;
    std::vector<GeneratorPtr> encoders;
    for (const std::string& name : evaluator_names) {
      checkpoints.push_back(FindCheckpoint(ctx, name));
      if (checkpoints.back().empty())
        return TaskReport::BadInput("eval_edit: input stage '" + name +
                                    "' holds no evaluator checkpoint");
      auto encoder = LoadGenerator(*plugins_, checkpoints.back());
      if (!encoder.ok()) return TaskReport::BadInput(encoder.status().message());
      encoders.push_back(std::move(*encoder));
    }
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
    EditSet set;
    set.generated = std::move(generated), set.targets = std::move(targets);
    set.sources = std::move(sources), set.edit_kinds = std::move(edit_kinds);
    set.batch = p.value("batch", int64_t{32});
    set.seed = p.value("seed", ctx.spec.seed());
    set.jitter_sigmas = p.value("jitter_yardsticks", std::vector<double>{});
    for (double sigma : set.jitter_sigmas) {
      if (!(sigma > 0 && sigma < 1))
        return TaskReport::BadInput("eval_edit: jitter_yardsticks are spreads in (0, 1) radians");
    }
    // Each evaluator's scores; with several, their mean (a judge less tied to one evaluator's
    // training) and each one's headline figures.
    std::vector<json> scores;
    json by_evaluator = json::array();
    for (size_t k = 0; k < encoders.size(); ++k) {
      auto scored = ScoreWith(*encoders[k], set);
      if (!scored.ok()) return TaskReport::Error("eval_edit: " + scored.status().message());
      const json& one = *scored;
      by_evaluator.push_back(
          {{"evaluator", checkpoints[k]},
           {"generated_to_target", one["generated_to_target"]["batches"]["R@1"]},
           {"generated_to_source", one["generated_to_source"]["batches"]["R@1"]},
           {"towards_target", one["towards_target"]["batches"]["R@1"]},
           {"copy_generated_to_target",
            one["yardsticks"]["copy"]["generated_to_target"]["batches"]["R@1"]}});
      scores.push_back(std::move(*scored));
    }
    json metrics = scores.size() == 1 ? scores.front() : MeanOf(scores);
    metrics.update(
        {{"evaluation", "edit"},  // its layout: configs/evaluations/edit.yaml
         {"method", method},
         {"evaluator", checkpoints.size() == 1 ? json(checkpoints[0]) : json(checkpoints)},
         {"motions", set.generated.size()},
         {"batch", set.batch},
         {"seed", set.seed}});
    if (checkpoints.size() > 1) metrics["by_evaluator"] = by_evaluator;
    if (p.contains("yardstick"))
      metrics["yardstick"] = p["yardstick"];  // "untrained": the report's untrained row
    if (p.contains("untrained_of"))  // the paper rows it is the untrained row of (default: all)
      metrics["untrained_of"] = p["untrained_of"];
    if (p.contains("row")) metrics["row"] = p["row"];  // its paper row (configs/papers)
    metrics["plausibility"] = {{"generated", MeanPlausibility(set.generated)},
                               {"target", MeanPlausibility(set.targets)}};
    const json& g2t = metrics["generated_to_target"]["all"];
    if (auto failed =
            RecordHistory(ctx, &metrics, method, edited_checkpoint, ids,
                          {{"generated_to_target.all.R@1", g2t["R@1"].get<double>(), true},
                           {"generated_to_target.all.AvgR", g2t["AvgR"].get<double>(), false}})) {
      return *failed;
    }
    if (Status st = WritePreview(ctx,
                                 {{"source", &set.sources[0]},
                                  {"edited", &set.generated[0]},
                                  {"target", &set.targets[0]}},
                                 edit_texts[0], ids[0]);
        !st.ok()) {
      return TaskReport::Error("eval_edit: " + st.message());
    }
    AddTiming(&metrics, started, set.generated.size() * encoders.size() * 3);
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
