#include "motionpipe/corpus/corpus.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>

#include "motionpipe/base/file.h"
#include "motionpipe/corpus/edits.h"
#include "motionpipe/corpus/synthesizer.h"
#include "motionpipe/formats/amass.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/plausibility.h"
#include "motionpipe/text/english.h"

namespace motionpipe::corpus {

namespace {

constexpr uint64_t kClipStream = 0xC11B;
constexpr uint64_t kMannerStream = 0x3A77E4;  // which texts state their manner
constexpr uint64_t kTripletStream = 0x7121;

bool PassesGate(const Synthesis& synthesis, const PlausibilityGate& gate,
                const Skeleton& skeleton) {
  if (synthesis.max_reach_error > gate.max_reach_error) return false;
  const PlausibilityReport r = EvaluateMotionPlausibility(skeleton, synthesis.motion);
  return r.foot_skate_ratio <= gate.max_skate_ratio && r.penetration_max <= gate.max_penetration &&
         r.max_joint_step <= gate.max_joint_step &&
         (!gate.joint_limits || r.joint_limit_violations == 0);
}

std::string StripSubject(const std::string& caption) {
  for (const char* subject : {"a person ", "someone ", "the person ", "a human ", "the human "}) {
    const std::string s(subject);
    if (caption.compare(0, s.size(), s) == 0) return caption.substr(s.size());
  }
  return caption;
}

// A HumanML3D-style description of the whole clip: base actions in order, gestures attached with
// "while" ("a person walks forward while waving right hand and then sits down").
std::string ClipCaption(const ClipScript& s) {
  std::string out;
  for (size_t k = 0; k < s.base.size(); ++k) {
    const ActionInstance& b = s.base[k];
    std::string part = k == 0 ? b.caption : StripSubject(b.caption);
    std::vector<std::string> during;
    for (const ActionInstance& o : s.overlays) {
      if (o.start >= b.start && o.start < b.end)
        during.push_back(text::GerundPhrase(VerbPhrase(o, Person::kThird)));
    }
    for (size_t j = 0; j < during.size(); ++j) part += (j == 0 ? " while " : " and ") + during[j];
    if (b.id == ActionId::kStand && !during.empty() && s.base.size() == 1) {
      part = "a person stands while " + during.front();
      for (size_t j = 1; j < during.size(); ++j) part += " and " + during[j];
    }
    out += (k == 0 ? "" : (k + 1 == s.base.size() ? " and then " : ", then ")) + part;
  }
  return out;
}

std::string ActCat(ActionId id) {
  switch (Def(id).kind) {
    case ActionKind::kLocomotion:
      return id == ActionId::kStand ? "stand" : "locomotion";
    case ActionKind::kWholeBody:
      return "body movement";
    case ActionKind::kLeg:
      return "leg movement";
    case ActionKind::kArm:
      return "arm movement";
    case ActionKind::kTorso:
      return "torso movement";
    case ActionKind::kHead:
      return "head movement";
  }
  return "action";
}

struct TextFact {
  std::string text;
  PartSet parts;
  std::string action;
};

struct GeneratedClip {
  Clip clip;
  nlohmann::json babel;
  std::string amass;
  std::string split;
  int64_t rejected = 0;
  std::vector<TextFact> facts;
};

Synthesis SynthesizeGated(ClipScript* script, const CorpusOptions& options, uint64_t base_seed,
                          const std::string& id, int64_t* rejected) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  Synthesis synthesis;
  for (int attempt = 0; attempt < options.gate.max_attempts; ++attempt) {
    Rng rng(MixSeed(base_seed, static_cast<uint64_t>(attempt)));
    *script = SampleScript(rng, options.script, id);
    synthesis = Synthesize(*script, skeleton);
    if (PassesGate(synthesis, options.gate, skeleton)) return synthesis;
    ++*rejected;
  }
  return synthesis;  // the last attempt, even if imperfect (never observed with the default gate)
}

GeneratedClip MakeClip(const CorpusOptions& options, int64_t index) {
  GeneratedClip out;
  char id[32];
  std::snprintf(id, sizeof(id), "c%07lld", static_cast<long long>(index));
  ClipScript script;
  const Synthesis synthesis = SynthesizeGated(
      &script, options, MixSeed(MixSeed(options.seed, kClipStream), index), id, &out.rejected);
  out.split = SplitOf(options.seed, kClipStream, index);
  Clip& clip = out.clip;
  clip.id = id;
  clip.source = "procedural:seed=" + std::to_string(options.seed);
  clip.motion = synthesis.motion;
  clip.joints = ComputeJoints(Skeleton::Smpl22(), clip.motion);
  if (options.manner_words > 0) {  // texts only: the motion is synthesized above
    Rng manner_rng(MixSeed(MixSeed(options.seed, kMannerStream), index));
    for (auto* list : {&script.base, &script.overlays}) {
      for (ActionInstance& a : *list) {
        if (manner_rng.Bernoulli(options.manner_words))
          a.label = WithManner(a.label, a.id, a.text_params());
        if (manner_rng.Bernoulli(options.manner_words))
          a.caption = WithManner(a.caption, a.id, a.text_params());
      }
    }
  }
  const std::string caption = ClipCaption(script);
  clip.texts.push_back(caption);
  clip.segments = synthesis.segments;
  // Segments follow script order: annotated base instances, then annotated overlays.
  std::vector<const ActionInstance*> annotated;
  for (const ActionInstance& a : script.base) {
    if (a.annotated) annotated.push_back(&a);
  }
  for (const ActionInstance& a : script.overlays) {
    if (a.annotated) annotated.push_back(&a);
  }
  for (size_t k = 0; k < clip.segments.size(); ++k) {
    clip.segments[k].action = Def(annotated[k]->id).name;
    clip.texts.push_back(annotated[k]->label);
    out.facts.push_back({annotated[k]->label, clip.segments[k].parts, clip.segments[k].action});
    out.facts.push_back({annotated[k]->caption, clip.segments[k].parts, clip.segments[k].action});
  }

  // BABEL: sequence label = the caption; frame labels = the actions, plus transitions as BABEL has.
  const std::string feat_p = "amass/" + clip.id + "_poses.npz";
  nlohmann::json frame_labels = nlohmann::json::array();
  int seg_id = 0;
  for (size_t k = 0; k < annotated.size(); ++k) {
    const ActionInstance& a = *annotated[k];
    frame_labels.push_back({{"raw_label", a.label},
                            {"proc_label", a.label},
                            {"seg_id", clip.id + "_" + std::to_string(seg_id++)},
                            {"act_cat", {ActCat(a.id)}},
                            {"start_t", std::round(a.start * 1000) / 1000},
                            {"end_t", std::round(a.end * 1000) / 1000}});
  }
  Rng transition_rng(MixSeed(MixSeed(options.seed, kClipStream ^ 0xBAB), index));
  for (size_t k = 1; k < script.base.size(); ++k) {
    if (!transition_rng.Bernoulli(0.3)) continue;
    const double t = script.base[k].start;
    frame_labels.push_back(
        {{"raw_label", "transition"},
         {"proc_label", "transition"},
         {"seg_id", clip.id + "_" + std::to_string(seg_id++)},
         {"act_cat", {"transition"}},
         {"start_t", std::round(std::max(0.0, t - 0.3) * 1000) / 1000},
         {"end_t", std::round(std::min(script.duration, t + 0.3) * 1000) / 1000}});
  }
  out.babel = {{"babel_sid", index},
               {"url", ""},
               {"feat_p", feat_p},
               {"dur", std::round(clip.motion.duration_seconds() * 1000) / 1000},
               {"split", out.split},
               {"seq_ann",
                {{"mul_act", annotated.size() > 1},
                 {"labels",
                  {{{"raw_label", caption},
                    {"proc_label", caption},
                    {"seg_id", clip.id + "_seq"},
                    {"act_cat", {"action"}}}}}}},
               {"frame_ann", {{"labels", frame_labels}}}};
  PartSet caption_parts = 0;  // the caption describes every action of the clip
  for (const ActionInstance& a : script.base)
    caption_parts = static_cast<PartSet>(caption_parts | PartsOf(a.id, a.side));
  for (const ActionInstance& a : script.overlays)
    caption_parts = static_cast<PartSet>(caption_parts | PartsOf(a.id, a.side));
  out.facts.push_back({caption, caption_parts, ""});
  if (options.write_amass) out.amass = SerializeNpz(AmassNpzFromMotion(clip.motion), false);
  return out;
}

struct GeneratedTriplet {
  Triplet triplet;
  int64_t rejected = 0;
  std::string error;  // set when the edit kinds asked for admit no triplet
};

// Scripts drawn for one triplet before giving up on the edit kinds asked for: a bound, so that a
// kind no script admits is an error, not an endless loop.
constexpr int kMaxEditDraws = 1000;

GeneratedTriplet MakeTriplet(const CorpusOptions& options, int64_t index) {
  GeneratedTriplet out;
  const Skeleton& skeleton = Skeleton::Smpl22();
  char id[32];
  std::snprintf(id, sizeof(id), "t%07lld", static_cast<long long>(index));
  const uint64_t base_seed = MixSeed(MixSeed(options.seed, kTripletStream), index);
  Triplet& t = out.triplet;
  for (int attempt = 0; attempt < options.gate.max_attempts; ++attempt) {
    Rng rng(MixSeed(base_seed, static_cast<uint64_t>(attempt)));
    ClipScript source = SampleScript(rng, options.script, id);
    std::optional<Edit> drawn = SampleEdit(source, rng, options.edit_kinds);
    for (int draw = 1; !drawn; ++draw) {  // only with fewer kinds than every kind
      if (draw == kMaxEditDraws) {
        out.error = "no script of " + std::to_string(kMaxEditDraws) + " drawn for triplet " + id +
                    " admits the edit kinds asked for";
        return out;
      }
      source = SampleScript(rng, options.script, id);
      drawn = SampleEdit(source, rng, options.edit_kinds);
    }
    const Edit& edit = *drawn;
    const Synthesis a = Synthesize(source, skeleton);
    const Synthesis b = Synthesize(edit.target, skeleton);
    t.source = a.motion;
    t.target = b.motion;
    t.text = edit.text;
    t.edit_kind = EditKindName(edit.kind);
    t.edit_start = static_cast<int32_t>(std::llround(edit.edit_start * options.fps));
    t.edit_end = static_cast<int32_t>(
        std::min<int64_t>(std::llround(edit.edit_end * options.fps), a.motion.num_frames()));
    if (PassesGate(a, options.gate, skeleton) && PassesGate(b, options.gate, skeleton)) break;
    ++out.rejected;
  }
  t.id = id;
  t.split = SplitOf(options.seed, kTripletStream, index);
  if (options.triplet_joints) {
    t.source_joints = ComputeJoints(skeleton, t.source);
    t.target_joints = ComputeJoints(skeleton, t.target);
  }
  return out;
}

std::string ShardName(const std::string& prefix, int64_t shard) {
  char name[64];
  std::snprintf(name, sizeof(name), "%s-%05lld.npz", prefix.c_str(), static_cast<long long>(shard));
  return name;
}

}  // namespace

std::string SplitOf(uint64_t seed, uint64_t stream, int64_t index) {
  const uint64_t h = MixSeed(MixSeed(seed, stream ^ 0x5B11), static_cast<uint64_t>(index)) % 100;
  return h < 80 ? "train" : (h < 90 ? "val" : "test");
}

namespace {

Status ValidateOptions(const CorpusOptions& options) {
  if (options.out_dir.empty()) return InvalidArgument("synth-corpus: no output directory");
  if (options.clips < 1) return InvalidArgument("synth-corpus: clips must be at least 1");
  if (options.triplets < -1) return InvalidArgument("synth-corpus: triplets must be >= 0");
  if (!(options.fps > 0)) return InvalidArgument("synth-corpus: fps must be positive");
  if (options.shard_size < 1) return InvalidArgument("synth-corpus: shard_size must be at least 1");
  if (const Status s = CheckMannerWords(options.manner_words); !s.ok())
    return InvalidArgument("synth-corpus: manner_words: " + s.message());
  return Status::Ok();
}

int64_t TripletCount(const CorpusOptions& options) {
  return options.triplets < 0 ? options.clips : options.triplets;
}

// Writes bytes under dir and records the file for the shard's file list.
Status WriteRecorded(const std::string& dir, const std::string& relative, const std::string& bytes,
                     bool sync, nlohmann::json* files) {
  MP_RETURN_IF_ERROR(WriteFileAtomic(dir + "/" + relative, bytes, sync));
  files->push_back({{"path", relative}, {"bytes", bytes.size()}, {"sha256", Sha256Hex(bytes)}});
  return Status::Ok();
}

}  // namespace

Status CheckMannerWords(double share) {
  if (share >= 0 && share <= 1) return Status::Ok();
  return InvalidArgument("a share in [0, 1] of texts, got " + std::to_string(share));
}

int64_t ShardCount(const CorpusOptions& options) {
  const int64_t size = std::max(1, options.shard_size);
  return std::max<int64_t>(1, (std::max(options.clips, TripletCount(options)) + size - 1) / size);
}

Status GenerateCorpusShard(const CorpusOptions& options, int64_t index, const std::string& dir) {
  MP_RETURN_IF_ERROR(ValidateOptions(options));
  if (index < 0 || index >= ShardCount(options))
    return InvalidArgument("corpus shard " + std::to_string(index) + " out of range");
  for (const char* sub : {"", "/clips", "/amass", "/motionfix"})
    MP_RETURN_IF_ERROR(MakeDirs(dir + sub));
  if (options.threads > 0) omp_set_num_threads(options.threads);
  CorpusOptions opts = options;
  opts.script.fps = options.fps;
  const int64_t size = options.shard_size;
  nlohmann::json files = nlohmann::json::array();
  nlohmann::json shard = {{"index", index}, {"rejected", 0}, {"frames", 0}, {"triplet_frames", 0}};
  nlohmann::json babel = nlohmann::json::object();
  nlohmann::json facts = nlohmann::json::array();
  std::map<std::string, int64_t> split_clips, edit_kinds;
  nlohmann::json triplet_splits = nlohmann::json::object();
  int64_t rejected = 0, frames = 0, triplet_frames = 0;

  const int64_t clip_begin = index * size, clip_end = std::min(options.clips, clip_begin + size);
  if (clip_begin < clip_end) {
    std::vector<GeneratedClip> generated(static_cast<size_t>(clip_end - clip_begin));
#pragma omp parallel for schedule(dynamic)
    for (int64_t k = 0; k < clip_end - clip_begin; ++k)
      generated[static_cast<size_t>(k)] = MakeClip(opts, clip_begin + k);
    std::vector<Clip> clips;
    for (GeneratedClip& g : generated) {
      rejected += g.rejected;
      frames += g.clip.motion.num_frames();
      split_clips[g.split] += 1;
      babel[g.split][std::to_string(g.babel["babel_sid"].get<int64_t>())] = g.babel;
      for (const TextFact& fact : g.facts) facts.push_back({fact.text, fact.parts, fact.action});
      if (options.write_amass) {
        MP_RETURN_IF_ERROR(
            WriteRecorded(dir, "amass/" + g.clip.id + "_poses.npz", g.amass, false, &files));
      }
      clips.push_back(std::move(g.clip));
    }
    MP_RETURN_IF_ERROR(WriteRecorded(dir, "clips/" + ShardName("clips", index),
                                     SerializeNpz(ClipsToNpz(clips), true), true, &files));
  }
  const int64_t triplet_begin = index * size,
                triplet_end = std::min(TripletCount(options), triplet_begin + size);
  if (triplet_begin < triplet_end) {
    std::vector<GeneratedTriplet> generated(static_cast<size_t>(triplet_end - triplet_begin));
#pragma omp parallel for schedule(dynamic)
    for (int64_t k = 0; k < triplet_end - triplet_begin; ++k)
      generated[static_cast<size_t>(k)] = MakeTriplet(opts, triplet_begin + k);
    std::vector<Triplet> triplets;
    for (GeneratedTriplet& g : generated) {
      if (!g.error.empty()) return InvalidArgument("corpus: " + g.error);
      rejected += g.rejected;
      triplet_frames += g.triplet.source.num_frames() + g.triplet.target.num_frames();
      triplet_splits[g.triplet.split].push_back(g.triplet.id);
      edit_kinds[g.triplet.edit_kind] += 1;
      triplets.push_back(std::move(g.triplet));
    }
    // Uncompressed (as np.savez): readers map the file and use the arrays in place; the filter and
    // the trainers read the triplets far more often than they are written.
    MP_RETURN_IF_ERROR(WriteRecorded(dir, "motionfix/" + ShardName("triplets", index),
                                     SerializeNpz(TripletsToNpz(triplets), false), true, &files));
  }
  shard["rejected"] = rejected;
  shard["frames"] = frames;
  shard["triplet_frames"] = triplet_frames;
  shard["clips"] = std::max<int64_t>(0, clip_end - clip_begin);
  shard["triplets"] = std::max<int64_t>(0, triplet_end - triplet_begin);
  shard["split_clips"] = split_clips;
  shard["edit_kinds"] = edit_kinds;
  shard["babel"] = babel;
  shard["triplet_splits"] = triplet_splits;
  shard["facts"] = facts;
  shard["files"] = files;
  return WriteFileAtomic(dir + "/shard.json", shard.dump() + "\n");
}

Result<CorpusSummary> FinalizeCorpus(const CorpusOptions& options,
                                     const std::vector<std::string>& shard_dirs) {
  MP_RETURN_IF_ERROR(ValidateOptions(options));
  const std::string& dir = options.out_dir;
  for (const char* sub : {"", "/clips", "/amass", "/babel", "/motionfix", "/texts"})
    MP_RETURN_IF_ERROR(MakeDirs(dir + sub));
  CorpusSummary summary;
  nlohmann::json manifest_files = nlohmann::json::array();
  std::map<std::string, nlohmann::json> babel;
  std::map<std::string, std::vector<double>>
      fact_parts;  // text -> summed part indicators (6) + count
  std::map<std::string, std::set<std::string>> fact_actions;
  nlohmann::json splits = {{"train", nlohmann::json::array()},
                           {"val", nlohmann::json::array()},
                           {"test", nlohmann::json::array()}};
  std::map<std::string, int64_t> edit_kinds;
  for (const std::string& shard_dir : shard_dirs) {
    MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(shard_dir + "/shard.json"));
    nlohmann::json shard;
    try {
      shard = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception& error) {
      return DataLoss(shard_dir + "/shard.json: " + error.what());
    }
    // The shard's files join the corpus as hard links (no copy); a copy where links are refused.
    for (const auto& file : shard["files"]) {
      const std::string relative = file["path"].get<std::string>();
      const std::string from = shard_dir + "/" + relative, to = dir + "/" + relative;
      std::error_code ec;
      std::filesystem::remove(to, ec);
      std::filesystem::create_hard_link(from, to, ec);
      if (ec) {
        std::filesystem::copy_file(from, to, std::filesystem::copy_options::overwrite_existing, ec);
        if (ec) return IoError(to + ": cannot link or copy from " + from + ": " + ec.message());
      }
      manifest_files.push_back(file);
    }
    summary.clips += shard["clips"].get<int64_t>();
    summary.triplets += shard["triplets"].get<int64_t>();
    summary.frames += shard["frames"].get<int64_t>();
    summary.triplet_frames += shard["triplet_frames"].get<int64_t>();
    summary.rejected += shard["rejected"].get<int64_t>();
    for (const auto& [split, count] : shard["split_clips"].items())
      summary.split_clips[split] += count.get<int64_t>();
    for (const auto& [kind, count] : shard["edit_kinds"].items())
      edit_kinds[kind] += count.get<int64_t>();
    for (const auto& [split, sequences] : shard["babel"].items()) {
      for (const auto& [sid, seq] : sequences.items()) babel[split][sid] = seq;
    }
    for (const auto& [split, ids] : shard["triplet_splits"].items()) {
      for (const auto& id : ids) splits[split].push_back(id);
    }
    for (const auto& fact : shard["facts"]) {
      const std::string text_key = fact[0].get<std::string>();
      const auto parts_bits = fact[1].get<int>();
      auto& parts = fact_parts[text_key];
      if (parts.empty()) parts.assign(kNumBodyParts + 1, 0.0);
      for (int p = 0; p < kNumBodyParts; ++p)
        parts[static_cast<size_t>(p)] += (parts_bits >> p) & 1;
      parts[kNumBodyParts] += 1;
      if (!fact[2].get<std::string>().empty())
        fact_actions[text_key].insert(fact[2].get<std::string>());
    }
  }
  const auto write_json = [&](const std::string& relative, const nlohmann::json& doc) -> Status {
    const std::string bytes = doc.dump(1) + "\n";
    MP_RETURN_IF_ERROR(WriteFileAtomic(dir + "/" + relative, bytes));
    manifest_files.push_back(
        {{"path", relative}, {"bytes", bytes.size()}, {"sha256", Sha256Hex(bytes)}});
    return Status::Ok();
  };
  for (const char* split : {"train", "val", "test"}) {
    MP_RETURN_IF_ERROR(write_json(std::string("babel/") + split + ".json",
                                  babel.count(split) ? babel[split] : nlohmann::json::object()));
  }
  MP_RETURN_IF_ERROR(write_json("motionfix/splits.json", splits));
  nlohmann::json labels = nlohmann::json::object();
  for (const auto& [text_key, parts] : fact_parts) {
    nlohmann::json fractions = nlohmann::json::array();
    for (int p = 0; p < kNumBodyParts; ++p) {
      fractions.push_back(std::round(parts[static_cast<size_t>(p)] / parts[kNumBodyParts] * 1000) /
                          1000);
    }
    labels[text_key] = {{"parts", fractions},
                        {"count", static_cast<int64_t>(parts[kNumBodyParts])}};
    if (fact_actions.count(text_key)) labels[text_key]["actions"] = fact_actions[text_key];
  }
  MP_RETURN_IF_ERROR(write_json("texts/labels.json",
                                {{"order", BodyPartNames()},
                                 {"about",
                                  "ground-truth body parts of every corpus text: the fraction of "
                                  "occurrences in which each part moves (1 always, 0 never, "
                                  "in between: the text does not say, e.g. 'wave' without a side)"},
                                 {"labels", labels}}));
  nlohmann::json manifest = {{"format", "motionpipe.corpus/1"},
                             {"seed", options.seed},
                             {"fps", options.fps},
                             {"clips", summary.clips},
                             {"triplets", summary.triplets},
                             {"frames", summary.frames},
                             {"triplet_frames", summary.triplet_frames},
                             {"rejected", summary.rejected},
                             {"split_clips", summary.split_clips},
                             {"edit_kinds", edit_kinds},
                             {"shard_size", options.shard_size},
                             {"vocabulary", Vocabulary().size()},
                             {"files", manifest_files}};
  if (options.edit_kinds != kEveryEditKind)
    manifest["edit_kinds_asked"] = EditKindNames(options.edit_kinds);
  if (options.manner_words > 0) manifest["manner_words"] = options.manner_words;
  MP_RETURN_IF_ERROR(WriteFileAtomic(dir + "/manifest.json", manifest.dump(1) + "\n"));
  return summary;
}

Result<CorpusSummary> GenerateCorpus(const CorpusOptions& options) {
  MP_RETURN_IF_ERROR(ValidateOptions(options));
  const auto started = std::chrono::steady_clock::now();
  const std::string shards_root = options.out_dir + "/.shards";
  std::vector<std::string> shard_dirs;
  for (int64_t index = 0; index < ShardCount(options); ++index) {
    shard_dirs.push_back(shards_root + "/" + std::to_string(index));
    MP_RETURN_IF_ERROR(GenerateCorpusShard(options, index, shard_dirs.back()));
  }
  MP_ASSIGN_OR_RETURN(CorpusSummary summary, FinalizeCorpus(options, shard_dirs));
  std::error_code ec;
  std::filesystem::remove_all(shards_root, ec);  // the corpus holds the other links to the files
  summary.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return summary;
}

}  // namespace motionpipe::corpus
