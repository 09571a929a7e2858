// `eval_generate`: scores generated motions against the ground truth (SINC Tables 2-3): the
// TEMOS score, APE/AVE, text-to-motion and motion-to-motion retrieval, diversity, plausibility.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <numeric>

#include "evaluation.h"
#include "inputs.h"
#include "motionpipe/base/random.h"
#include "motionpipe/eval/metrics.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/sinc/spans.h"
#include "motionpipe/sinc/synth.h"
#include "motionpipe/sinc/texts.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// One motion's TEMOS score: (1 + cos(f_gt, f_gen)) / 2 (REFERENCE 4.6); the TEMOS score is its
// mean.
double TemosScoreOf(const std::vector<float>& generated, const std::vector<float>& truth) {
  return (1 + Cosine(generated, truth)) / 2;
}

// What eval_generate measures of motions against their ground truth (SINC Tables 2-3), from their
// TEMOS-evaluator features and TMR embeddings: the TEMOS score, APE/AVE, and TMR retrieval
// text-to-generated and generated-to-truth (batches and all).
Result<json> GenerationScores(const std::vector<Motion>& generated,
                              const std::vector<Motion>& truth,
                              const std::vector<std::vector<float>>& g_temos,
                              const std::vector<std::vector<float>>& t_temos,
                              const eval::Embeddings& gen, const eval::Embeddings& gt,
                              const eval::Embeddings& txt, int64_t batch, uint64_t seed) {
  // TEMOS score: mean over the test motions of each one's (REFERENCE 4.6).
  double temos_score = 0;
  for (size_t i = 0; i < generated.size(); ++i) temos_score += TemosScoreOf(g_temos[i], t_temos[i]);
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

// How well the TMR evaluator finds a motion from its text (and back) among pairs of one kind, and
// the mean cosine of each motion to its own text.
Result<json> TextMotionAgreement(plugin::Generator& tmr, const std::vector<Motion>& motions,
                                 const std::vector<std::string>& texts, int64_t batch,
                                 uint64_t seed) {
  MP_ASSIGN_OR_RETURN(auto m_rows, tmr.EncodeMotions(motions));
  MP_ASSIGN_OR_RETURN(auto t_rows, tmr.EncodeTexts(texts));
  double cosine = 0;
  for (size_t i = 0; i < m_rows.size(); ++i) cosine += Cosine(m_rows[i], t_rows[i]);
  const auto m = ToEmbeddings(m_rows), t = ToEmbeddings(t_rows);
  const int64_t b = std::min<int64_t>(batch, static_cast<int64_t>(motions.size()));
  MP_ASSIGN_OR_RETURN(const auto text_to_motion, eval::Retrieval(t, m, b, seed));
  MP_ASSIGN_OR_RETURN(const auto motion_to_text, eval::Retrieval(m, t, b, seed));
  return json{{"motions", motions.size()},
              {"text_motion_cosine", cosine / static_cast<double>(motions.size())},
              {"text_to_motion", ScoresJson(text_to_motion)},
              {"motion_to_text", ScoresJson(motion_to_text)}};
}

// TextMotionAgreement on real spans of the table, each with its text.
Result<json> SpansAgreement(plugin::Generator& tmr, const sinc::SpanTable& table,
                            const std::vector<int64_t>& spans, int64_t batch, uint64_t seed) {
  std::vector<Motion> motions;
  std::vector<std::string> texts;
  for (const int64_t i : spans)
    motions.push_back(table.MotionOf(i)), texts.push_back(SpanText(table, i));
  return TextMotionAgreement(tmr, motions, texts, batch, seed);
}

// The TMR evaluator's own retrieval on the held-out test split (issue 15): text-to-motion and
// motion-to-text R@1/R@3 in batches, on single actions and on two-action spans ("A while B").
Result<json> EvaluatorQuality(plugin::Generator& tmr, const sinc::SpanTable& table, int64_t batch,
                              uint64_t seed) {
  json out;
  for (const char* kind : {"singles", "pairs"}) {
    const auto spans = SelectSpans(table, {{"split", "test"}, {"spans", kind}});
    if (spans.size() < 2) continue;
    MP_ASSIGN_OR_RETURN(out[kind], SpansAgreement(tmr, table, spans, batch, seed));
  }
  return out;
}

// Do SINC's synthetic pairs show what their texts say (issue 15: label-guided compositions do not
// beat random ones here)? `count` pairs drawn from the split's singles as training draws them on
// the fly (a single, a partner of disjoint parts: PairSampler::Draw, not checked), once with the
// body parts of their labels and once with random parts, with the evaluation's text ("A while
// B"), beside each pair's first single alone with the same text, the label-guided pairs' singles
// composed by random parts (labels_random_parts: the parts alone differ) and `count` of the
// split's real two-action spans; each scored by TextMotionAgreement.
Result<json> SyntheticPairAgreement(plugin::Generator& tmr, const sinc::SpanTable& table,
                                    int64_t count, const std::string& split, int64_t batch,
                                    uint64_t seed) {
  if (count < 2) return InvalidArgument("synthetic_pairs: at least 2 pairs");
  json out = {{"split", split}};
  for (const sinc::PartSource parts : {sinc::PartSource::kLabels, sinc::PartSource::kRandom}) {
    sinc::SynthOptions options;
    options.parts = parts;
    options.split = split;
    const sinc::PairSampler sampler(table, options);
    Rng rng(MixSeed(seed, parts == sinc::PartSource::kLabels ? 1 : 2)), repart(MixSeed(seed, 4));
    std::vector<Motion> motions, firsts, reparted;
    std::vector<std::string> texts;
    sinc::PairRecipe recipe;
    while (static_cast<int64_t>(motions.size()) < count && sampler.Draw(rng, &recipe)) {
      motions.push_back(sinc::MaterialiseMotion(table, recipe, options.crop));
      firsts.push_back(table.MotionOf(recipe.first));
      if (parts == sinc::PartSource::kLabels) {  // the same two singles, random parts
        sinc::PairRecipe random = recipe;
        sinc::DrawRandomParts(repart, &random);
        reparted.push_back(sinc::MaterialiseMotion(table, random, options.crop));
      }
      texts.push_back(sinc::EvalPairText(table.text_a[static_cast<size_t>(recipe.first)],
                                         table.text_a[static_cast<size_t>(recipe.second)]));
    }
    if (static_cast<int64_t>(motions.size()) < 2)
      return InvalidArgument("synthetic_pairs: split '" + split + "' has no compatible singles");
    const std::string kind = parts == sinc::PartSource::kLabels ? "labels" : "random";
    MP_ASSIGN_OR_RETURN(out[kind], TextMotionAgreement(tmr, motions, texts, batch, seed));
    // The yardstick: each pair's first single alone for the pair's text (what the TMR finds
    // without the second action composed in).
    MP_ASSIGN_OR_RETURN(out[kind + "_first_alone"],
                        TextMotionAgreement(tmr, firsts, texts, batch, seed));
    if (!reparted.empty()) {  // the parts alone decide: label-guided singles, random parts
      MP_ASSIGN_OR_RETURN(out["labels_random_parts"],
                          TextMotionAgreement(tmr, reparted, texts, batch, seed));
    }
  }
  std::vector<int64_t> real = SelectSpans(table, {{"split", split}, {"spans", "pairs"}});
  Rng rng(MixSeed(seed, 3));
  for (size_t k = real.size(); k > 1; --k)  // a seeded sample, not the first spans
    std::swap(real[k - 1], real[static_cast<size_t>(rng.Int(0, static_cast<int>(k) - 1))]);
  if (static_cast<int64_t>(real.size()) > count) real.resize(static_cast<size_t>(count));
  if (real.size() >= 2) {
    MP_ASSIGN_OR_RETURN(out["real_pairs"], SpansAgreement(tmr, table, real, batch, seed));
  }
  return out;
}

// Can the TEMOS score tell a label-guided composition from a random one (issue 15: the generators
// trained on each tie by it)? A yardstick made of data, no generator: each two-action span
// (A while B) of `spans` is composed again from two real single actions whose texts are exactly A
// and B (of the span's split where there is one, each the one nearest in length), once with the
// labeler's body parts of each (what SINC's synthetic pairs and GPT-compositing do) and once with
// random parts (the paper's random-composition ablation, DrawRandomParts), beside the single A
// alone (what a single-action model could at best give). Each is scored against the span's ground
// truth as a generation is, on the spans whose two singles exist with compatible labelled parts
// (their ids are listed, to pair a generator's per_motion scores with them); the paired per-span
// difference of the TEMOS score (labels - random, labels - A alone) with its standard error says
// how far apart the metric puts the two kinds of composition before any model learns from them.
Result<json> ComposedTruth(plugin::Generator& tmr, plugin::Generator& temos,
                           const sinc::SpanTable& table, const std::vector<int64_t>& spans,
                           int64_t batch, uint64_t seed) {
  // Singles by text. The corpus words an action many ways, so few test spans find both texts
  // among the test singles alone: a single of the span's split is preferred, else one of any split
  // (a yardstick of data, no model trains on it), each time the one nearest in length.
  std::map<std::string, std::vector<int64_t>> singles;
  for (int64_t j = 0; j < table.size(); ++j)
    if (table.single(j)) singles[table.text_a[static_cast<size_t>(j)]].push_back(j);
  const auto nearest = [&](int64_t span, const std::string& text) -> int64_t {
    const auto it = singles.find(text);
    if (it == singles.end()) return -1;
    const auto key = [&](int64_t j) {
      return std::pair{
          table.splits[static_cast<size_t>(j)] != table.splits[static_cast<size_t>(span)],
          std::abs(table.frames(j) - table.frames(span))};
    };
    int64_t best = -1;
    for (const int64_t j : it->second)
      if (best < 0 || key(j) < key(best)) best = j;
    return best;
  };
  Rng rng(MixSeed(seed, 6));
  std::vector<Motion> labels, random, alone, truths;
  std::vector<std::string> texts;
  json ids = json::array();
  int64_t pairs = 0, unmatched = 0, incompatible = 0;
  for (const int64_t span : spans) {
    if (table.single(span)) continue;
    ++pairs;
    const int64_t a = nearest(span, table.text_a[static_cast<size_t>(span)]),
                  b = nearest(span, table.text_b[static_cast<size_t>(span)]);
    if (a < 0 || b < 0) {
      ++unmatched;
      continue;
    }
    sinc::PairRecipe recipe;
    recipe.first = static_cast<int32_t>(a), recipe.second = static_cast<int32_t>(b);
    recipe.first_parts = table.parts_a[static_cast<size_t>(a)] & sinc::kAllParts;
    recipe.second_parts = table.parts_a[static_cast<size_t>(b)] & sinc::kAllParts;
    if (!sinc::Compatible(recipe.first_parts, recipe.second_parts)) {
      ++incompatible;
      continue;
    }
    labels.push_back(sinc::MaterialiseMotion(table, recipe, sinc::CropMode::kFirst));
    sinc::DrawRandomParts(rng, &recipe);
    random.push_back(sinc::MaterialiseMotion(table, recipe, sinc::CropMode::kFirst));
    alone.push_back(table.MotionOf(a));
    truths.push_back(table.MotionOf(span));
    texts.push_back(SpanText(table, span));
    ids.push_back(table.ids[static_cast<size_t>(span)]);
  }
  json out = {{"pairs", pairs},
              {"unmatched", unmatched},
              {"incompatible", incompatible},
              {"spans", labels.size()}};
  if (labels.size() < 2) return out;
  out["ids"] = std::move(ids);
  MP_ASSIGN_OR_RETURN(const auto t_temos, temos.EncodeMotions(truths));
  MP_ASSIGN_OR_RETURN(const auto t_tmr, tmr.EncodeMotions(truths));
  MP_ASSIGN_OR_RETURN(const auto text_tmr, tmr.EncodeTexts(texts));
  const auto gt = ToEmbeddings(t_tmr), txt = ToEmbeddings(text_tmr);
  const int64_t b = std::min<int64_t>(batch, static_cast<int64_t>(truths.size()));
  std::map<std::string, std::vector<double>> per_span;
  for (const auto& [key, motions] :
       {std::pair<const char*, const std::vector<Motion>*>{"labels", &labels},
        {"random", &random},
        {"first_alone", &alone}}) {
    MP_ASSIGN_OR_RETURN(const auto f_temos, temos.EncodeMotions(*motions));
    MP_ASSIGN_OR_RETURN(const auto f_tmr, tmr.EncodeMotions(*motions));
    MP_ASSIGN_OR_RETURN(out[key], GenerationScores(*motions, truths, f_temos, t_temos,
                                                   ToEmbeddings(f_tmr), gt, txt, b, seed));
    for (size_t k = 0; k < f_temos.size(); ++k)
      per_span[key].push_back(TemosScoreOf(f_temos[k], t_temos[k]));
  }
  // Paired by span: mean difference, its sd and standard error.
  const auto paired = [&](const std::string& x, const std::string& y) {
    const auto& u = per_span[x];
    const auto& v = per_span[y];
    const double n = static_cast<double>(u.size());
    double mean = 0, ss = 0;
    for (size_t k = 0; k < u.size(); ++k) mean += (u[k] - v[k]) / n;
    for (size_t k = 0; k < u.size(); ++k) ss += std::pow(u[k] - v[k] - mean, 2);
    const double sd = std::sqrt(ss / (n - 1));
    return json{{"mean", mean}, {"sd", sd}, {"se", sd / std::sqrt(n)}, {"n", u.size()}};
  };
  out["temos_score_difference"] = {{"labels_minus_random", paired("labels", "random")},
                                   {"labels_minus_first_alone", paired("labels", "first_alone")}};
  return out;
}

// A generate stage's motions with a span in the table (the first sample of each: extra samples,
// "id#k", are skipped), each with its span, text and ground truth; the method and checkpoint its
// summaries name.
struct GeneratedMotions {
  std::vector<Motion> generated, truth;
  std::vector<std::string> texts, ids;
  std::vector<int64_t> spans;  // each motion's span in the table
};

Result<GeneratedMotions> ReadGenerated(const TaskContext& ctx, const std::string& stage,
                                       const sinc::SpanTable& table, std::string* method,
                                       std::string* checkpoint) {
  std::map<std::string, int64_t> span_of;
  for (int64_t i = 0; i < table.size(); ++i) span_of[table.ids[static_cast<size_t>(i)]] = i;
  GeneratedMotions out;
  for (const std::string& dir : StageDirs(ctx, stage)) {
    if (!fs::exists(dir + "/generated.npz")) continue;
    MP_ASSIGN_OR_RETURN(std::vector<Clip> clips, ReadClips(dir + "/generated.npz"));
    for (auto& clip : clips) {
      const auto it = span_of.find(clip.id);
      if (it == span_of.end()) continue;  // extra samples ("id#k") and unknown ids
      out.ids.push_back(clip.id);
      out.spans.push_back(it->second);
      out.texts.push_back(clip.texts.empty() ? std::string() : clip.texts[0]);
      out.generated.push_back(std::move(clip.motion));
      out.truth.push_back(table.MotionOf(it->second));
    }
    ReadSummary(dir + "/generate.json", method, checkpoint);
  }
  return out;
}

// params: evaluator (TMR: retrieval), temos (TEMOS on real singles: the TEMOS score; default the
// evaluator), generated (the generate stage), singles (the spans and ground truth; default the
// input that has them; each of these an input's name or a path pattern such as
// "out/demo-1/gen_sinc"), batch (32), seed, diversity_pairs (300), method.
// yardstick ("untrained": the report's untrained generator), evaluator_quality (true: also the
// TMR's own retrieval on the test singles and two-action spans), synthetic_pairs (N > 0: also the
// TMR's agreement of text and motion on N synthetic pairs of each kind and N real pairs of
// `synthetic_split`, default train: SyntheticPairAgreement), composed_truth (true: also the
// yardsticks of ComposedTruth: each generated two-action span, or with `composed_split` every
// two-action span of that split, composed from two real singles by labelled and by random parts).
class EvalGenerateStage : public StageExecutor {
 public:
  // One task.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    CheckInputParams(plan, path, {"evaluator", "temos", "generated", "singles"}, errors);
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
    auto table = InputSpans(ctx, p.value("singles", std::string()));
    if (!table.ok()) return TaskReport::BadInput("eval_generate: " + table.status().message());
    // The generated motions (first sample of each span) and their ground truth.
    std::string method = p.value("method", std::string()), generated_checkpoint;
    auto read = ReadGenerated(ctx, p.value("generated", std::string()), *table, &method,
                              &generated_checkpoint);
    if (!read.ok()) return TaskReport::BadInput(read.status().message());
    auto& [generated, truth, texts, ids, spans] = *read;
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
    // Each motion's TEMOS score by span id, so that a subset of the spans (e.g. the action pairs
    // the training never held, tools/pair_coverage.py) can be scored and paired by span.
    json per_motion = json::array();
    for (size_t i = 0; i < generated.size(); ++i)
      per_motion.push_back(
          {{"id", ids[i]}, {"temos_score", TemosScoreOf((*g_temos)[i], (*t_temos)[i])}});
    metrics["per_motion"] = std::move(per_motion);
    metrics.update({{"evaluation", "generate"},  // its layout: configs/evaluations/generate.yaml
                    {"method", method},
                    {"motions", generated.size()},
                    {"batch", batch},
                    {"seed", seed}});
    if (p.contains("yardstick"))
      metrics["yardstick"] = p["yardstick"];  // "untrained": the report's untrained row
    if (p.contains("untrained_of"))  // the paper rows it is the untrained row of (default: all)
      metrics["untrained_of"] = p["untrained_of"];
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
    if (const int64_t n = p.value("synthetic_pairs", int64_t{0}); n > 0) {
      auto agreement = SyntheticPairAgreement(
          **tmr, *table, n, p.value("synthetic_split", std::string("train")), batch, seed);
      if (!agreement.ok())
        return TaskReport::BadInput("eval_generate: " + agreement.status().message());
      metrics["synthetic_pairs"] = *agreement;
    }
    if (p.value("composed_truth", false)) {  // the generated spans, or every pair of a split
      std::vector<int64_t> composed_spans = spans;
      if (p.contains("composed_split")) {
        const json& split = p["composed_split"];
        composed_spans = split.is_string()
                             ? SelectSpans(*table, {{"split", split}, {"spans", "pairs"}})
                             : std::vector<int64_t>{};
        if (composed_spans.empty())
          return TaskReport::BadInput(
              "eval_generate: composed_split " +
              (split.is_string() ? "'" + split.get<std::string>() + "'" : split.dump()) +
              " has no two-action spans (a split name: train, val or test)");
      }
      auto composed = ComposedTruth(**tmr, temos_encoder, *table, composed_spans, batch, seed);
      if (!composed.ok()) return TaskReport::Error("eval_generate: " + composed.status().message());
      metrics["yardsticks"]["composed"] = *composed;
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

MP_STAGE_KIND("eval_generate", EvalGenerateStage);

}  // namespace motionpipe::stages
