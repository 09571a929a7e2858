// The procedural corpus (issue 3): vocabulary, synthesis quality, joint performance of simultaneous
// actions, editing triplets, determinism and readability through the real loaders.
#include "motionpipe/corpus/corpus.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "motionpipe/base/file.h"
#include "motionpipe/corpus/edits.h"
#include "motionpipe/corpus/inspect.h"
#include "motionpipe/corpus/synthesizer.h"
#include "motionpipe/formats/amass.h"
#include "motionpipe/formats/babel.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/plausibility.h"

namespace motionpipe::corpus {
namespace {

const Skeleton& Smpl() { return Skeleton::Smpl22(); }

// A script of one action between a second of standing before and after (or under a base action).
ClipScript SingleAction(ActionId id, uint64_t seed, ActionId base_id = ActionId::kStand) {
  Rng rng(seed);
  ClipScript s;
  s.style = SampleStyle(rng);
  ActionInstance a = SampleInstance(id, rng);
  const double length = a.duration();
  if (IsBaseKind(Def(id).kind)) {
    ActionInstance before = SampleInstance(ActionId::kStand, rng),
                   after = SampleInstance(ActionId::kStand, rng);
    before.start = 0;
    before.end = 1;
    a.start = 1;
    a.end = 1 + length;
    after.start = a.end;
    after.end = a.end + 1.2;
    if (id == ActionId::kStandUp) {
      s.start_seated = true;
      a.start = 0;
      a.end = length;
      after.start = a.end;
      after.end = a.end + 1.2;
      s.base = {a, after};
    } else {
      s.base = {before, a, after};
    }
  } else {
    ActionInstance base = SampleInstance(base_id, rng);
    base.start = 0;
    base.end = length + 1.5;
    a.start = 0.6;
    a.end = 0.6 + length;
    s.base = {base};
    s.overlays = {a};
  }
  s.duration = s.base.back().end;
  return s;
}

void ExpectPlausible(const Synthesis& synthesis, const std::string& what) {
  const PlausibilityReport r = EvaluateMotionPlausibility(Smpl(), synthesis.motion);
  EXPECT_LE(r.foot_skate_ratio, 0.08) << what;
  EXPECT_LE(r.penetration_max, 0.01) << what;
  EXPECT_EQ(r.joint_limit_violations, 0) << what << ": " << r.worst_joint_limit;
  EXPECT_LT(r.bone_length_error, 1e-4) << what;
  EXPECT_LT(r.max_joint_step, 0.9) << what;
  EXPECT_LT(synthesis.max_reach_error, 0.01) << what;
  EXPECT_TRUE(ValidateMotion(synthesis.motion, what).ok());
}

TEST(Vocabulary, FortyPlusActionsOverAllSixParts) {
  EXPECT_GE(kNumActions, 40);
  PartSet covered = 0;
  for (const ActionDef& def : Vocabulary()) {
    EXPECT_GE(def.labels.size(), 3u) << def.name;
    EXPECT_GE(def.captions.size(), 2u) << def.name;
    for (Side side : {Side::kLeft, Side::kRight}) {
      covered |= PartsOf(def.id, side);
      TextParams params{side, 1.5, 1, 3, false};
      for (const std::string& t : def.labels)
        EXPECT_EQ(FillTemplate(t, params).find('{'), std::string::npos) << t;
      for (const std::string& t : def.captions)
        EXPECT_EQ(FillTemplate(t, params).find('{'), std::string::npos) << t;
    }
    EXPECT_NE(PartsOf(def.id, Side::kRight), 0) << def.name;
    EXPECT_EQ(ActionByName(def.name), def.id);
  }
  EXPECT_EQ(covered, 0x3F);
  EXPECT_EQ(PartsOf(ActionId::kWave, Side::kRight), PartBit(BodyPart::kRightArm));
  EXPECT_EQ(PartsOf(ActionId::kKick, Side::kLeft), PartBit(BodyPart::kLeftLeg));
  EXPECT_EQ(FillTemplate("wave {hand} {speed}", {Side::kLeft, 1.5, 1, 0, true}),
            "wave left hand quickly");
}

TEST(Vocabulary, MannerIsStatedOnlyWhenOffNormalAndNotTwice) {
  const TextParams fast_big{Side::kRight, 1.5, 1.3, 3, false};
  EXPECT_EQ(WithManner("wave right hand", ActionId::kWave, fast_big),
            "wave right hand quickly three times with big movements");
  EXPECT_EQ(WithManner("wave right hand", ActionId::kWave, {Side::kRight, 0.7, 0.7, 1, false}),
            "wave right hand slowly once with small movements");
  // Normal tempo and size, no repetitions: the text as it was.
  EXPECT_EQ(WithManner("wave right hand", ActionId::kWave, {Side::kRight, 1.1, 1.0, 0, false}),
            "wave right hand");
  // What the text already says is not said again ("slowly" is not "low"; "sprint" is fast).
  EXPECT_EQ(WithManner("wave right hand quickly twice", ActionId::kWave, fast_big),
            "wave right hand quickly twice with big movements");
  EXPECT_EQ(WithManner("sprint", ActionId::kRun, fast_big), "sprint");
  EXPECT_EQ(WithManner("kick slowly", ActionId::kKick, {Side::kLeft, 0.7, 1.3, 0, false}),
            "kick slowly with big movements");
  EXPECT_EQ(WithManner("kick high", ActionId::kKick, {Side::kLeft, 1, 1.3, 0, false}), "kick high");
  // Each only where it is a parameter of the motion: a walk has no size or count, standing no
  // tempo.
  EXPECT_EQ(WithManner("walk forward", ActionId::kWalk, fast_big), "walk forward quickly");
  EXPECT_EQ(WithManner("stand", ActionId::kStand, fast_big), "stand");
}

TEST(Synthesizer, EveryActionAloneIsPhysicallyPlausible) {
  for (const ActionDef& def : Vocabulary()) {
    for (uint64_t seed : {1u, 2u, 3u}) {
      ExpectPlausible(
          Synthesize(SingleAction(def.id, MixSeed(seed, static_cast<uint64_t>(def.id)))), def.name);
    }
  }
}

TEST(Synthesizer, GesturesWhileWalkingArePhysicallyPlausible) {
  for (const ActionDef& def : Vocabulary()) {
    if (def.kind != ActionKind::kArm && def.kind != ActionKind::kHead) continue;
    ExpectPlausible(Synthesize(SingleAction(def.id, MixSeed(9, static_cast<uint64_t>(def.id)),
                                            ActionId::kWalk)),
                    std::string(def.name) + " while walking");
  }
}

TEST(Synthesizer, RandomScriptsRarelyFailThePlausibilityGate) {
  int failures = 0;
  const int n = 200;
  for (int i = 0; i < n; ++i) {
    Rng rng(MixSeed(77, static_cast<uint64_t>(i)));
    const Synthesis s = Synthesize(SampleScript(rng, {}, "x"));
    const PlausibilityReport r = EvaluateMotionPlausibility(Smpl(), s.motion);
    failures += r.foot_skate_ratio > 0.08 || r.penetration_max > 0.01 ||
                r.joint_limit_violations > 0 || s.max_reach_error > 0.01;
  }
  EXPECT_LE(failures, n * 3 / 100) << failures << " of " << n;
}

// Horizontal speed of the pelvis over frames [a, b).
double PelvisSpeed(const Motion& m, int64_t a, int64_t b) {
  const Vec3 d = m.Translation(b - 1) - m.Translation(a);
  return std::hypot(d.x, d.y) / (static_cast<double>(b - 1 - a) / m.fps);
}

TEST(Synthesizer, WavingWhileWalkingIsPerformedJointly) {
  // The same walk, once plain and once while waving the right hand.
  Rng rng(5);
  ClipScript walk;
  walk.style = SampleStyle(rng);
  ActionInstance w = SampleInstance(ActionId::kWalk, rng);
  w.start = 0;
  w.end = 8;
  w.speed = 1;
  walk.base = {w};
  walk.duration = 8;
  ClipScript waving = walk;
  ActionInstance wave = SampleInstance(ActionId::kWave, rng);
  wave.side = Side::kRight;
  wave.start = 2;
  wave.end = 6;
  waving.overlays = {wave};
  const Motion plain = Synthesize(walk).motion, joint = Synthesize(waving).motion;
  // The pace slows while the hand waves...
  EXPECT_LT(PelvisSpeed(joint, 90, 150), 0.95 * PelvisSpeed(plain, 90, 150));
  const std::vector<float> jp = ComputeJoints(Smpl(), plain), jj = ComputeJoints(Smpl(), joint);
  const auto z = [](const std::vector<float>& j, int64_t f, int joint_index) {
    return j[static_cast<size_t>((f * 22 + joint_index) * 3 + 2)];
  };
  // ...the waving hand is up by the head instead of swinging...
  for (int64_t f = 100; f < 150; f += 5) EXPECT_GT(z(jj, f, 21), z(jj, f, 17) + 0.1) << f;
  // ...and the other arm swings less than in the plain walk (relative to the pelvis, along the
  // walk).
  const auto swing = [&](const std::vector<float>& j, const Motion& m) {
    double lo = 1e9, hi = -1e9;
    for (int64_t f = 100; f < 150; ++f) {
      const Vec3 forward = m.LocalRotation(f, 0) * Vec3{0, 0, 1};
      const Vec3 rel{
          j[static_cast<size_t>((f * 22 + 20) * 3)] - j[static_cast<size_t>(f * 66)],
          j[static_cast<size_t>((f * 22 + 20) * 3 + 1)] - j[static_cast<size_t>(f * 66 + 1)], 0};
      const double along = Dot(rel, forward);
      lo = std::min(lo, along);
      hi = std::max(hi, along);
    }
    return hi - lo;
  };
  EXPECT_LT(swing(jj, joint), 0.8 * swing(jp, plain));
  // Outside the wave the two performances are the same walk.
  EXPECT_NEAR(z(jj, 20, 21), z(jp, 20, 21), 1e-6);
}

// Mean speed (m/s) of the joints of one body part over a motion.
double PartSpeed(const Motion& m, BodyPart part) {
  const std::vector<float> j = ComputeJoints(Smpl(), m);
  double sum = 0;
  int64_t n = 0;
  for (int joint : Smpl().part_joints()[static_cast<size_t>(part)]) {
    for (int64_t f = 1; f < m.num_frames(); ++f) {
      double d2 = 0;
      for (int c = 0; c < 3; ++c) {
        const double d = j[static_cast<size_t>((f * 22 + joint) * 3 + c)] -
                         j[static_cast<size_t>(((f - 1) * 22 + joint) * 3 + c)];
        d2 += d * d;
      }
      sum += std::sqrt(d2) * m.fps;
      ++n;
    }
  }
  return sum / static_cast<double>(n);
}

TEST(Synthesizer, TheSameActionVariesWithItsParameters) {
  // Side: a right-hand wave moves the right arm, a left-hand wave the left one.
  ClipScript s = SingleAction(ActionId::kWave, 21);
  s.overlays[0].side = Side::kRight;
  const Motion right = Synthesize(s).motion;
  s.overlays[0].side = Side::kLeft;
  const Motion left = Synthesize(s).motion;
  EXPECT_GT(PartSpeed(right, BodyPart::kRightArm), 2 * PartSpeed(right, BodyPart::kLeftArm));
  EXPECT_GT(PartSpeed(left, BodyPart::kLeftArm), 2 * PartSpeed(left, BodyPart::kRightArm));
  // Tempo: the same walk at a higher speed covers more ground in the same time.
  ClipScript walk = SingleAction(ActionId::kWalk, 22);
  walk.base[1].speed = 0.7;
  const double slow = PelvisSpeed(Synthesize(walk).motion, 45, 75);
  walk.base[1].speed = 1.4;
  const double fast = PelvisSpeed(Synthesize(walk).motion, 45, 75);
  EXPECT_GT(fast, 1.5 * slow);
}

TEST(Synthesizer, DifferentActionsShareCoarseStatistics) {
  // A model cannot tell these apart from how much each body part moves: it has to read the text.
  const std::pair<ActionId, ActionId> confusable[] = {{ActionId::kKick, ActionId::kKneeLift},
                                                      {ActionId::kSalute, ActionId::kScratchHead},
                                                      {ActionId::kNod, ActionId::kShakeHead},
                                                      {ActionId::kSquat, ActionId::kCrouch}};
  for (const auto& [a, b] : confusable) {
    for (BodyPart part :
         {BodyPart::kGlobal, BodyPart::kTorso, BodyPart::kRightArm, BodyPart::kRightLeg}) {
      double sa = 0, sb = 0;
      for (uint64_t seed = 1; seed <= 4; ++seed) {
        ClipScript ca = SingleAction(a, seed), cb = SingleAction(b, seed);
        for (ActionInstance* i : {&ca.base.back(), ca.overlays.empty() ? nullptr : &ca.overlays[0]})
          if (i) i->side = Side::kRight;
        for (ActionInstance* i : {&cb.base.back(), cb.overlays.empty() ? nullptr : &cb.overlays[0]})
          if (i) i->side = Side::kRight;
        if (IsBaseKind(Def(a).kind)) ca.base[1].side = Side::kRight;
        if (IsBaseKind(Def(b).kind)) cb.base[1].side = Side::kRight;
        sa += PartSpeed(Synthesize(ca).motion, part);
        sb += PartSpeed(Synthesize(cb).motion, part);
      }
      EXPECT_LT(std::abs(sa - sb), 0.6 * std::max(sa, sb) + 0.02)
          << Def(a).name << " vs " << Def(b).name << " part " << static_cast<int>(part);
    }
  }
}

TEST(Synthesizer, StandingIsAliveButStill) {
  const Motion m = Synthesize(SingleAction(ActionId::kStand, 3)).motion;
  double lo = 1e9, hi = -1e9;
  for (int64_t f = 0; f < m.num_frames(); ++f) {
    lo = std::min(lo, m.Translation(f).x);
    hi = std::max(hi, m.Translation(f).x);
  }
  EXPECT_GT(hi - lo, 0.002);  // idle sway: never frozen
  EXPECT_LT(hi - lo, 0.05);
}

TEST(Synthesizer, SegmentsFollowTheScript) {
  ClipScript s = SingleAction(ActionId::kKick, 4);
  s.base[1].side = Side::kLeft;
  const Synthesis syn = Synthesize(s);
  ASSERT_EQ(syn.segments.size(), 3u);
  EXPECT_EQ(syn.segments[1].start_frame, 30);
  EXPECT_EQ(syn.segments[1].parts, PartBit(BodyPart::kLeftLeg));
  EXPECT_EQ(syn.segments[1].text, s.base[1].label);
  EXPECT_EQ(syn.motion.num_frames(), s.num_frames());
}

TEST(Edits, EveryKindOccursWithTextAndRange) {
  std::set<std::string> kinds;
  for (int i = 0; i < 300; ++i) {
    Rng rng(MixSeed(31, static_cast<uint64_t>(i)));
    const ClipScript source = SampleScript(rng, {}, "s");
    const std::optional<Edit> drawn = SampleEdit(source, rng);
    ASSERT_TRUE(drawn.has_value());  // with every kind, some edit always applies
    const Edit& edit = *drawn;
    kinds.insert(EditKindName(edit.kind));
    EXPECT_FALSE(edit.text.empty());
    EXPECT_EQ(edit.text.find('{'), std::string::npos) << edit.text;
    EXPECT_LT(edit.edit_start, edit.edit_end);
    EXPECT_LE(edit.edit_end, source.duration + 1e-9);
    EXPECT_GT(edit.target.duration, 0.5);
    for (size_t k = 1; k < edit.target.base.size(); ++k)
      EXPECT_NEAR(edit.target.base[k].start, edit.target.base[k - 1].end, 1e-9);
  }
  EXPECT_EQ(kinds.size(), static_cast<size_t>(EditKind::kCount));
}

TEST(Edits, KindsAskedForAreTheOnlyKindsMade) {
  const auto side = ParseEditKinds({"side"});
  ASSERT_TRUE(side.ok());
  EXPECT_EQ(ParseEditKinds({}).value(), kEveryEditKind);
  EXPECT_EQ(EditKindNames(*side), std::vector<std::string>{"side"});
  const auto bad = ParseEditKinds({"side", "mirror"});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("'mirror'"), std::string::npos);
  EXPECT_NE(bad.status().message().find("replace_base"), std::string::npos);  // lists the known
  int made = 0, none = 0;
  for (int i = 0; i < 200; ++i) {
    Rng rng(MixSeed(37, static_cast<uint64_t>(i)));
    const ClipScript source = SampleScript(rng, {}, "s");
    const std::optional<Edit> edit = SampleEdit(source, rng, *side);
    if (!edit) {
      ++none;
      continue;
    }
    ++made;
    EXPECT_EQ(edit->kind, EditKind::kSide) << edit->text;
  }
  EXPECT_GT(made, 20);  // side edits apply to many scripts, not to all
  EXPECT_GT(none, 0);
}

TEST(Corpus, EditKindsRestrictTheTriplets) {
  const std::string root = testing::TempDir() + "/corpus_kinds";
  std::filesystem::remove_all(root);
  CorpusOptions options;
  options.clips = 4, options.triplets = 24, options.shard_size = 24, options.write_amass = false;
  options.out_dir = root + "/every";
  ASSERT_TRUE(GenerateCorpus(options).ok());
  CorpusOptions amplitude = options;
  amplitude.edit_kinds = ParseEditKinds({"amplitude"}).value();
  amplitude.out_dir = root + "/amplitude";
  ASSERT_TRUE(GenerateCorpus(amplitude).ok());
  const auto manifest = nlohmann::json::parse(*ReadFile(root + "/amplitude/manifest.json"));
  EXPECT_EQ(manifest["edit_kinds"], (nlohmann::json{{"amplitude", 24}}));
  EXPECT_EQ(manifest["edit_kinds_asked"], (nlohmann::json{"amplitude"}));
  EXPECT_FALSE(
      nlohmann::json::parse(*ReadFile(root + "/every/manifest.json")).contains("edit_kinds_asked"));
  std::filesystem::remove_all(root);
}

TEST(Corpus, MannerWordsChangeOnlyTheTexts) {
  const std::string root = testing::TempDir() + "/corpus_manner";
  std::filesystem::remove_all(root);
  CorpusOptions plain;
  plain.clips = 24, plain.triplets = 12, plain.shard_size = 24;
  plain.out_dir = root + "/plain";
  ASSERT_TRUE(GenerateCorpus(plain).ok());
  CorpusOptions manner = plain;
  manner.manner_words = 1;
  manner.out_dir = root + "/manner";
  ASSERT_TRUE(GenerateCorpus(manner).ok());
  const auto a = nlohmann::json::parse(*ReadFile(plain.out_dir + "/manifest.json"));
  const auto b = nlohmann::json::parse(*ReadFile(manner.out_dir + "/manifest.json"));
  EXPECT_FALSE(a.contains("manner_words"));
  EXPECT_EQ(b["manner_words"], 1.0);
  // The motions and the triplets are the same bytes; the clips' texts and annotations are not.
  std::map<std::string, std::string> sha;
  for (const auto& f : a["files"]) sha[f["path"]] = f["sha256"];
  int same = 0, differ = 0;
  for (const auto& f : b["files"]) {
    const std::string path = f["path"];
    const bool texts = path.rfind("clips/", 0) == 0 || path.rfind("babel/", 0) == 0 ||
                       path.rfind("texts/", 0) == 0;
    if (texts) {
      differ += sha[path] != f["sha256"].get<std::string>() ? 1 : 0;
    } else {
      EXPECT_EQ(sha[path], f["sha256"].get<std::string>()) << path;
      ++same;
    }
  }
  EXPECT_GT(same, 24);   // the AMASS files and the triplets
  EXPECT_GE(differ, 3);  // the clips, BABEL and the labels file
  auto clips_a = ReadClips(plain.out_dir + "/clips/clips-00000.npz");
  auto clips_b = ReadClips(manner.out_dir + "/clips/clips-00000.npz");
  ASSERT_TRUE(clips_a.ok() && clips_b.ok());
  ASSERT_EQ(clips_a->size(), clips_b->size());
  int stated = 0;
  for (size_t i = 0; i < clips_a->size(); ++i) {
    const Clip &x = (*clips_a)[i], &y = (*clips_b)[i];
    EXPECT_EQ(x.motion.poses, y.motion.poses);
    ASSERT_EQ(x.texts.size(), y.texts.size());
    for (size_t k = 1; k < x.texts.size(); ++k) {  // the segments' labels (0: the caption)
      EXPECT_EQ(y.texts[k].rfind(x.texts[k], 0), 0u)
          << "a manner is appended, never a different label: " << x.texts[k] << " / " << y.texts[k];
      stated += x.texts[k] != y.texts[k] ? 1 : 0;
    }
  }
  EXPECT_GT(stated, 5);
  manner.manner_words = 1.5;
  EXPECT_FALSE(GenerateCorpus(manner).ok());
  std::filesystem::remove_all(root);
}

class CorpusTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(::testing::TempDir() + "/corpus_a");
    std::filesystem::remove_all(*dir_);
    CorpusOptions options;
    options.out_dir = *dir_;
    options.seed = 11;
    options.clips = 90;
    options.triplets = 60;
    options.shard_size = 40;
    options.threads = 2;
    auto summary = GenerateCorpus(options);
    ASSERT_TRUE(summary.ok()) << summary.status().ToString();
    summary_ = new CorpusSummary(*summary);
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete summary_;
  }
  static std::string* dir_;
  static CorpusSummary* summary_;
};
std::string* CorpusTest::dir_ = nullptr;
CorpusSummary* CorpusTest::summary_ = nullptr;

TEST_F(CorpusTest, SameSeedSameBytesWhateverTheThreadCount) {
  CorpusOptions options;
  options.out_dir = ::testing::TempDir() + "/corpus_b";
  std::filesystem::remove_all(options.out_dir);
  options.seed = 11;
  options.clips = 90;
  options.triplets = 60;
  options.shard_size = 40;
  options.threads = 1;
  ASSERT_TRUE(GenerateCorpus(options).ok());
  // The manifest lists the sha256 of every file, so equal manifests mean equal corpora.
  EXPECT_EQ(*ReadFile(*dir_ + "/manifest.json"), *ReadFile(options.out_dir + "/manifest.json"));
  options.seed = 12;
  options.out_dir += "_other_seed";
  ASSERT_TRUE(GenerateCorpus(options).ok());
  EXPECT_NE(*ReadFile(*dir_ + "/manifest.json"), *ReadFile(options.out_dir + "/manifest.json"));
}

TEST_F(CorpusTest, ManifestChecksumsMatchTheFiles) {
  const nlohmann::json manifest = nlohmann::json::parse(*ReadFile(*dir_ + "/manifest.json"));
  EXPECT_EQ(manifest["clips"], 90);
  EXPECT_EQ(manifest["triplets"], 60);
  EXPECT_GT(manifest["files"].size(), 90u);
  for (const auto& file : manifest["files"]) {
    auto bytes = ReadFile(*dir_ + "/" + file["path"].get<std::string>());
    ASSERT_TRUE(bytes.ok()) << file["path"];
    EXPECT_EQ(Sha256Hex(*bytes), file["sha256"].get<std::string>()) << file["path"];
  }
}

TEST_F(CorpusTest, TheRealLoadersReadEveryFormat) {
  // Our clip shards, with ground-truth segments and plausible motions.
  int64_t clips = 0;
  for (const char* shard : {"clips-00000.npz", "clips-00001.npz", "clips-00002.npz"}) {
    auto loaded = ReadClips(*dir_ + "/clips/" + shard);
    ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
    for (const Clip& clip : *loaded) {
      ++clips;
      EXPECT_FALSE(clip.texts.empty());
      EXPECT_FALSE(clip.segments.empty());
      for (const Segment& seg : clip.segments) {
        EXPECT_NE(seg.parts, 0);
        EXPECT_NE(ActionByName(seg.action), ActionId::kCount) << seg.action;
      }
      const PlausibilityReport r = EvaluateMotionPlausibility(Smpl(), clip.motion);
      EXPECT_LE(r.foot_skate_ratio, 0.08) << clip.id;
      EXPECT_LE(r.penetration_max, 0.01) << clip.id;
      EXPECT_EQ(r.joint_limit_violations, 0) << clip.id;
      EXPECT_LT(r.bone_length_error, 1e-4) << clip.id;
      // AMASS-style twin of the clip, through the AMASS reader.
      auto amass = ReadAmassNpz(*dir_ + "/amass/" + clip.id + "_poses.npz", 0);
      ASSERT_TRUE(amass.ok()) << amass.status().ToString();
      EXPECT_EQ(amass->motion.poses, clip.motion.poses);
    }
  }
  EXPECT_EQ(clips, 90);
  // BABEL-style annotations: the sweep finds single actions and simultaneous pairs.
  int64_t singles = 0, pairs = 0, sequences = 0;
  for (const char* split : {"train", "val", "test"}) {
    auto babel = ReadBabel(*dir_ + "/babel/" + split + ".json");
    ASSERT_TRUE(babel.ok()) << babel.status().ToString();
    for (const BabelSequence& seq : *babel) {
      ++sequences;
      EXPECT_TRUE(std::filesystem::exists(*dir_ + "/" + seq.feat_p)) << seq.feat_p;
      for (const ActionSpan& span : SweepActionSpans(seq, {}))
        (span.labels.size() == 1 ? singles : pairs) += 1;
    }
  }
  EXPECT_EQ(sequences, 90);
  EXPECT_GT(singles, 60);
  EXPECT_GT(pairs, 30);
  // MotionFix-style triplets with edit ranges and kinds.
  auto triplets = ReadTriplets(*dir_ + "/motionfix/triplets-00000.npz");
  ASSERT_TRUE(triplets.ok()) << triplets.status().ToString();
  for (const Triplet& t : *triplets) {
    EXPECT_FALSE(t.text.empty());
    EXPECT_FALSE(t.edit_kind.empty());
    EXPECT_GE(t.edit_start, 0);
    EXPECT_GT(t.edit_end, t.edit_start);
    EXPECT_EQ(t.source_joints.size(), static_cast<size_t>(t.source.num_frames()) * 66);
  }
}

TEST_F(CorpusTest, EditsChangeTheEditedFramesAndOnlyRoughlyTheRest) {
  // For gesture additions/removals (timing unchanged), the target departs from the source inside
  // the edited range and follows it closely, but not exactly, outside.
  double inside = 0, outside = 0, exact_outside = 0;
  int64_t n_inside = 0, n_outside = 0;
  for (const char* shard : {"triplets-00000.npz", "triplets-00001.npz"}) {
    auto triplets = ReadTriplets(*dir_ + "/motionfix/" + shard);
    ASSERT_TRUE(triplets.ok());
    for (const Triplet& t : *triplets) {
      if (t.edit_kind != "add_action" && t.edit_kind != "remove_action") continue;
      const int64_t frames = std::min(t.source.num_frames(), t.target.num_frames());
      for (int64_t f = 0; f < frames; ++f) {
        double d = 0;
        for (int k = 0; k < 66; ++k) {
          d = std::max(
              d, static_cast<double>(std::abs(t.source_joints[static_cast<size_t>(f * 66 + k)] -
                                              t.target_joints[static_cast<size_t>(f * 66 + k)])));
        }
        const bool edited = f >= t.edit_start && f < t.edit_end;
        (edited ? inside : outside) += d;
        (edited ? n_inside : n_outside) += 1;
        if (!edited && d == 0) exact_outside += 1;
      }
    }
  }
  ASSERT_GT(n_inside, 0);
  ASSERT_GT(n_outside, 0);
  EXPECT_GT(inside / n_inside, 3 * outside / n_outside);
  EXPECT_LT(exact_outside / n_outside, 0.01);  // never bit-exact
}

TEST_F(CorpusTest, LabelsCarryGroundTruthParts) {
  const nlohmann::json labels = nlohmann::json::parse(*ReadFile(*dir_ + "/texts/labels.json"));
  ASSERT_TRUE(labels.contains("labels"));
  int checked = 0;
  for (const auto& [text, entry] : labels["labels"].items()) {
    const auto parts = entry["parts"].get<std::vector<double>>();
    ASSERT_EQ(parts.size(), 6u);
    if (text.find("right hand") != std::string::npos && text.find("both") == std::string::npos &&
        entry.contains("actions") && entry["actions"].size() == 1 &&
        Def(ActionByName(entry["actions"][0])).kind == ActionKind::kArm) {
      EXPECT_EQ(parts[3], 1.0) << text;  // right arm
      EXPECT_EQ(parts[2], 0.0) << text;  // not the left arm
      ++checked;
    }
  }
  EXPECT_GT(checked, 0);
}

TEST_F(CorpusTest, InspectSummarizesThroughTheLoaders) {
  auto report = InspectCorpus(*dir_);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_EQ(report->clips, 90);
  EXPECT_EQ(report->triplets, 60);
  EXPECT_GT(report->actions.size(), 30u);
  EXPECT_GT(report->babel_pairs, 30);
  EXPECT_EQ(report->joint_limit_violations, 0);
  EXPECT_LE(report->skate_max, 0.08);
  const std::string text = FormatCorpusReport(*report);
  EXPECT_NE(text.find("clips: 90"), std::string::npos);
  EXPECT_NE(text.find("triplets: 60"), std::string::npos);
  EXPECT_FALSE(InspectCorpus(::testing::TempDir() + "/no_such_corpus").ok());
}

}  // namespace
}  // namespace motionpipe::corpus
