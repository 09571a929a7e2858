// SINC: body-part composition (paper sec. 3.1), text augmentation, and the fast 135-d features.
#include <gtest/gtest.h>

#include <filesystem>
#include <set>

#include "motionpipe/base/file.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/sinc/composition.h"
#include "motionpipe/sinc/texts.h"
#include "test_util.h"

namespace motionpipe::sinc {
namespace {

using testing::SmoothMotion;

constexpr PartSet kGlobal = PartBit(BodyPart::kGlobal), kTorso = PartBit(BodyPart::kTorso),
                  kLeftArm = PartBit(BodyPart::kLeftArm), kRightArm = PartBit(BodyPart::kRightArm),
                  kLeftLeg = PartBit(BodyPart::kLeftLeg), kRightLeg = PartBit(BodyPart::kRightLeg);
constexpr PartSet kLegs = kLeftLeg | kRightLeg;

bool SameJoint(const Motion& a, int64_t fa, const Motion& b, int64_t fb, int joint) {
  for (int k = 0; k < 3; ++k) {
    if (a.poses[static_cast<size_t>((fa * kNumJoints + joint) * 3 + k)] !=
        b.poses[static_cast<size_t>((fb * kNumJoints + joint) * 3 + k)])
      return false;
  }
  return true;
}

bool SameTrans(const Motion& a, int64_t fa, const Motion& b, int64_t fb) {
  for (int k = 0; k < 3; ++k) {
    if (a.trans[static_cast<size_t>(fa * 3 + k)] != b.trans[static_cast<size_t>(fb * 3 + k)])
      return false;
  }
  return true;
}

TEST(Composition, CompatibilityIsDisjointNonEmptyParts) {
  EXPECT_TRUE(Compatible(kLegs | kGlobal, kRightArm));
  EXPECT_FALSE(Compatible(kLegs, kRightLeg | kRightArm));
  EXPECT_FALSE(Compatible(0, kRightArm));
}

TEST(Composition, ArmWaveOnAWalk) {
  // A walk (legs + global) and a right-arm wave: B = the wave (fewer parts) gives the right arm;
  // the walk keeps legs, global orientation and translation.
  const Motion walk = SmoothMotion(90, 1), wave = SmoothMotion(60, 2);
  CompositionPlan plan;
  const Motion out = Compose(walk, kLegs | kGlobal, wave, kRightArm, CropMode::kFirst, &plan);
  EXPECT_FALSE(plan.swapped);
  EXPECT_FALSE(plan.root_from_b);
  ASSERT_EQ(out.num_frames(), 60);  // step 1: trimmed to the shorter
  const auto& parts = Skeleton::Smpl22().part_joints();
  for (int64_t f = 0; f < 60; ++f) {
    for (int j = 0; j < kNumJoints; ++j) {
      const bool arm = std::find(parts[3].begin(), parts[3].end(), j) != parts[3].end();
      EXPECT_TRUE(arm ? SameJoint(out, f, wave, f, j) : SameJoint(out, f, walk, f, j))
          << f << " " << j;
    }
    EXPECT_TRUE(SameTrans(out, f, walk, f));
  }
}

TEST(Composition, OrderCropAndLegsTravelTogether) {
  // First argument has fewer parts: step 2 swaps. B (the kick: left leg) uses a leg, so B also
  // gives both legs, the global orientation and the translation (step 3); A (arms + torso) keeps
  // the rest.
  const Motion kick = SmoothMotion(50, 3), gesture = SmoothMotion(80, 4);
  CompositionPlan plan;
  const Motion out =
      Compose(kick, kLeftLeg, gesture, kTorso | kLeftArm | kRightArm, CropMode::kCentre, &plan);
  EXPECT_TRUE(plan.swapped);
  EXPECT_TRUE(plan.root_from_b);
  EXPECT_EQ(plan.from_b, kLegs | kGlobal);
  EXPECT_EQ(plan.frames, 50);
  EXPECT_EQ(plan.a_start, 15);  // centred crop of the 80-frame gesture
  EXPECT_EQ(plan.b_start, 0);
  for (int64_t f = 0; f < 50; ++f) {
    EXPECT_TRUE(SameTrans(out, f, kick, f));
    EXPECT_TRUE(SameJoint(out, f, kick, f, 0));           // global orientation
    EXPECT_TRUE(SameJoint(out, f, kick, f, 5));           // right knee (the other leg comes along)
    EXPECT_TRUE(SameJoint(out, f, gesture, f + 15, 9));   // spine3
    EXPECT_TRUE(SameJoint(out, f, gesture, f + 15, 21));  // right wrist
  }
  // Equal part counts keep the given order; B's parts override A's when they overlap (step 5).
  const Motion over = Compose(gesture, kRightArm, kick, kRightArm, CropMode::kFirst, &plan);
  EXPECT_FALSE(plan.swapped);
  for (int64_t f = 0; f < 50; ++f) EXPECT_TRUE(SameJoint(over, f, kick, f, 19));
}

TEST(Composition, FastFeaturesMatchTheReferenceEncoder) {
  for (uint32_t seed : {5u, 6u, 7u}) {
    Motion m = SmoothMotion(73, seed);
    // A rotation past pi exercises the wrap.
    m.poses[static_cast<size_t>((10 * kNumJoints + 4) * 3)] = 4.0f;
    const FeatureMatrix slow = EncodeTemos135(m);
    std::vector<float> fast(static_cast<size_t>(73 * kTemosFeatureDim));
    EncodeTemos135Fast(m.poses.data(), m.trans.data(), 73, fast.data());
    double worst = 0;
    for (size_t k = 0; k < fast.size(); ++k)
      worst = std::max(worst, static_cast<double>(std::fabs(fast[k] - slow.data[k])));
    EXPECT_LT(worst, 2e-6) << seed;
  }
}

TEST(Texts, FivePatternsWithEnglishGerunds) {
  EXPECT_EQ(PairText("walk forward", "wave right hand", PairPattern::kWhile),
            "walk forward while waving right hand");
  EXPECT_EQ(PairText("walk", "sit down", PairPattern::kDuring), "walk during sitting down");
  EXPECT_EQ(PairText("stand", "lie down", PairPattern::kWhile), "stand while lying down");
  EXPECT_EQ(PairText("a", "b", PairPattern::kSimultaneously), "simultaneously a and b");
  EXPECT_EQ(PairText("a", "b", PairPattern::kComma), "a, b");
  EXPECT_EQ(PairText("a", "b", PairPattern::kAtTheSameTime), "a and b at the same time");
  EXPECT_EQ(GerundOfLabel("swings arms forward"), "swinging arms forward");
  EXPECT_EQ(GerundOfLabel("gallops forward"), "galloping forward");
  EXPECT_EQ(GerundOfLabel("reaches up"), "reaching up");
  EXPECT_EQ(GerundOfLabel("a person walks in a circle"), "walking in a circle");
  EXPECT_EQ(GerundOfLabel("someone is jogging"), "jogging");
  EXPECT_EQ(GerundOfLabel("jumping jacks"), "jumping jacks");
  EXPECT_EQ(GerundOfLabel("hop on one leg"), "hopping on one leg");
  EXPECT_EQ(GerundOfLabel("cross arms"), "crossing arms");
  EXPECT_EQ(GerundOfLabel("kneel"), "kneeling");
  EXPECT_EQ(EvalPairText("walk", "clap"), "walk while clapping");
}

TEST(Texts, AugmentationCoversPatternsAndOrders) {
  Rng rng(3);
  std::set<std::string> seen;
  std::set<int> patterns;
  int swapped_count = 0;
  for (int k = 0; k < 400; ++k) {
    PairPattern pattern;
    bool swapped = false;
    seen.insert(AugmentPairText("walk", "wave", rng, &pattern, &swapped));
    patterns.insert(static_cast<int>(pattern));
    swapped_count += swapped;
  }
  EXPECT_EQ(patterns.size(), 5u);
  EXPECT_EQ(seen.size(), 10u);  // 5 patterns x 2 orders
  EXPECT_GT(swapped_count, 150);
  EXPECT_LT(swapped_count, 250);
  EXPECT_TRUE(seen.count("wave while walking"));
  EXPECT_TRUE(seen.count("simultaneously walk and wave"));
}

}  // namespace
}  // namespace motionpipe::sinc

#include "motionpipe/labels/labeler.h"
#include "motionpipe/sinc/spans.h"
#include "motionpipe/sinc/synth.h"

namespace motionpipe::sinc {
namespace {

// A spans table of smooth motions with the given labels and parts.
SpanTable MakeTable(const std::vector<std::pair<std::string, PartSet>>& singles) {
  SpanTable table;
  uint32_t seed = 10;
  for (const auto& [text, parts] : singles) {
    table.Add("s" + std::to_string(seed), "train", "test",
              testing::SmoothMotion(40 + static_cast<int64_t>(seed % 7) * 5, seed), text, "");
    table.parts_a.back() = parts;
    ++seed;
  }
  return table;
}

TEST(Synth, SamplerDrawsOnlyCompatiblePartners) {
  const SpanTable table = MakeTable({{"walk", kLegs | kGlobal},
                                     {"wave right hand", kRightArm},
                                     {"nod", kTorso},
                                     {"jump", kLegs | kGlobal},
                                     {"clap", kLeftArm | kRightArm},
                                     {"kick", kLegs}});
  SynthOptions options;
  const PairSampler sampler(table, options);
  EXPECT_EQ(sampler.singles(), 6);
  Rng rng(1);
  std::set<std::pair<int, int>> seen;
  for (int k = 0; k < 500; ++k) {
    PairRecipe r;
    ASSERT_TRUE(sampler.Draw(rng, &r));
    EXPECT_TRUE(Compatible(r.first_parts, r.second_parts));
    EXPECT_EQ(r.first_parts, table.parts_a[static_cast<size_t>(r.first)]);
    seen.insert({r.first, r.second});
  }
  EXPECT_GT(seen.size(), 10u);
  // The on-the-fly mode: a partner for a given single.
  PairRecipe r;
  ASSERT_TRUE(sampler.DrawPartner(0, rng, &r));
  EXPECT_EQ(r.first, 0);
  EXPECT_TRUE(Compatible(kLegs | kGlobal, r.second_parts));
  // Random parts (the ablation) ignore the labels but stay disjoint.
  options.parts = PartSource::kRandom;
  const PairSampler random(table, options);
  for (int k = 0; k < 200; ++k) {
    ASSERT_TRUE(random.Draw(rng, &r));
    EXPECT_TRUE(Compatible(r.first_parts, r.second_parts))
        << int(r.first_parts) << " " << int(r.second_parts);
  }
}

TEST(Synth, RecipesMaterialiseTheSameMotionFeaturesAndText) {
  const SpanTable table = MakeTable(
      {{"walk forward", kLegs | kGlobal}, {"wave right hand", kRightArm}, {"nod", kTorso}});
  PairRecipe r;
  r.first = 0;
  r.second = 1;
  r.first_parts = kLegs | kGlobal;
  r.second_parts = kRightArm;
  r.pattern = static_cast<uint8_t>(PairPattern::kWhile);
  EXPECT_EQ(MaterialiseText(table, r), "walk forward while waving right hand");
  r.text_swapped = 1;
  EXPECT_EQ(MaterialiseText(table, r), "wave right hand while walking forward");
  const Motion m = MaterialiseMotion(table, r, CropMode::kCentre);
  const Motion direct =
      Compose(table.MotionOf(0), kLegs | kGlobal, table.MotionOf(1), kRightArm, CropMode::kCentre);
  EXPECT_EQ(m.poses, direct.poses);
  EXPECT_EQ(m.trans, direct.trans);
  std::vector<float> a(static_cast<size_t>(m.num_frames() * kTemosFeatureDim)), b(a.size());
  EXPECT_EQ(MaterialiseFeatures(table, r, CropMode::kCentre, a.data()), m.num_frames());
  EncodeTemos135Fast(m.poses.data(), m.trans.data(), m.num_frames(), b.data());
  EXPECT_EQ(a, b);
}

// Standing still, waving the right arm: no foot moves.
Motion StandingWave(int64_t frames) {
  Motion m = Motion::Rest(frames, 30, Skeleton::Smpl22().RestPelvisHeight());
  for (int64_t f = 0; f < frames; ++f)
    m.SetLocalRotation(f, 17,
                       AxisAngleToMatrix({0, 0, 0.8 * std::sin(0.3 * static_cast<double>(f))}));
  return m;
}

TEST(Synth, ChecksCatchPenetrationAndJumps) {
  const Motion m = StandingWave(60);
  const CompositionScores fine = ScoreComposition(m);
  EXPECT_EQ(FailedCheck(fine, CompositionChecks{}), "")
      << fine.skate_ratio << " " << fine.penetration << " " << fine.max_step;
  EXPECT_LT(fine.penetration, 1e-4);
  EXPECT_LT(fine.skate_ratio, 1e-6);
  Motion teleport = m;
  for (int64_t f = 30; f < 60; ++f) teleport.trans[static_cast<size_t>(f * 3)] += 2.0f;
  EXPECT_EQ(FailedCheck(ScoreComposition(teleport), CompositionChecks{}), "joint_jump");
  // Two frames sink 30 cm into the floor (the floor comes from the other frames' feet).
  Motion sink = m;
  for (int64_t f = 30; f < 32; ++f) sink.trans[static_cast<size_t>(f * 3 + 2)] -= 0.3f;
  const CompositionScores sunk = ScoreComposition(sink);
  EXPECT_NEAR(sunk.penetration, 0.3, 0.01);
  EXPECT_EQ(FailedCheck(sunk, CompositionChecks{}), "floor_penetration");
  // Feet sliding along the floor while planted.
  Motion slide = m;
  for (int64_t f = 0; f < 60; ++f)
    slide.trans[static_cast<size_t>(f * 3)] += 0.02f * static_cast<float>(f);
  EXPECT_EQ(FailedCheck(ScoreComposition(slide), CompositionChecks{}), "foot_skate");
}

TEST(Synth, ShardsAreDeterministicAndIndependentOfThreads) {
  SpanTable table = MakeTable({{"walk", kLegs | kGlobal},
                               {"wave", kRightArm},
                               {"nod", kTorso},
                               {"jump", kLegs | kGlobal},
                               {"clap", kLeftArm | kRightArm},
                               {"look around", kTorso}});
  const std::string dir = ::testing::TempDir() + "/synth_shards";
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(WriteSpans(dir + ".npz", table).ok());
  auto mapped = ReadSpans(dir + ".npz");
  ASSERT_TRUE(mapped.ok()) << mapped.status().ToString();
  EXPECT_EQ(mapped->text_a, table.text_a);
  EXPECT_EQ(mapped->parts_a, table.parts_a);
  SynthOptions options;
  options.seed = 5;
  options.checks.max_skate_ratio = 1.5;  // the test motions slide their feet
  auto one = SynthesizeShard(*mapped, options, 3, 300, 1, dir + "/one");
  auto two = SynthesizeShard(*mapped, options, 3, 300, 2, dir + "/two");
  auto other = SynthesizeShard(*mapped, options, 4, 300, 2, dir + "/other");
  ASSERT_TRUE(one.ok() && two.ok() && other.ok()) << one.status().ToString();
  EXPECT_EQ(one->pairs, 300);
  EXPECT_EQ(*ReadFile(dir + "/one/pairs.npz"), *ReadFile(dir + "/two/pairs.npz"));
  EXPECT_NE(*ReadFile(dir + "/one/pairs.npz"), *ReadFile(dir + "/other/pairs.npz"));
  auto back = ReadPairs(dir + "/one/pairs.npz");
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->recipes.size(), 300u);
  for (const PairRecipe& r : back->recipes) EXPECT_TRUE(Compatible(r.first_parts, r.second_parts));
  // Too strict checks fail the shard with a clear message instead of looping.
  options.checks.max_skate_ratio = -1;
  auto strict = SynthesizeShard(*mapped, options, 0, 10, 1, dir + "/strict");
  ASSERT_FALSE(strict.ok());
  EXPECT_NE(strict.status().message().find("passed the checks"), std::string::npos);
}

}  // namespace
}  // namespace motionpipe::sinc

namespace motionpipe::labels {
namespace {

TEST(Labels, GptAnswersAreMappedWithSincsRules) {
  const PartSet LA = PartBit(BodyPart::kLeftArm), RA = PartBit(BodyPart::kRightArm),
                G = PartBit(BodyPart::kGlobal), T = PartBit(BodyPart::kTorso),
                LL = PartBit(BodyPart::kLeftLeg), RL = PartBit(BodyPart::kRightLeg);
  EXPECT_EQ(PartsFromGptAnswer("Answer: right leg\nleft leg\nbuttocks\nwaist"), G | LL | RL);
  EXPECT_EQ(PartsFromGptAnswer("Answer: torso\nneck"), T);
  EXPECT_EQ(PartsFromGptAnswer("Answer: shoulders"), LA | RA);
  EXPECT_EQ(PartsFromGptAnswer("Answer: right shoulder, hand, right eye"), RA);
  EXPECT_EQ(PartsFromGptAnswer("none of the above"), 0);
}

TEST(Labels, LexiconReadsSidesPluralsNegationAndObjects) {
  const PartSet LA = PartBit(BodyPart::kLeftArm), RA = PartBit(BodyPart::kRightArm),
                G = PartBit(BodyPart::kGlobal), T = PartBit(BodyPart::kTorso),
                LL = PartBit(BodyPart::kLeftLeg), RL = PartBit(BodyPart::kRightLeg);
  EXPECT_EQ(LexiconParts("walk forward"), G | LL | RL);
  EXPECT_EQ(LexiconParts("raise left arm"), LA);
  EXPECT_EQ(LexiconParts("raise both arms"), LA | RA);
  EXPECT_EQ(LexiconParts("kick with the right foot"), RL);
  EXPECT_EQ(LexiconParts("walking while waving the right hand"), G | LL | RL | RA);
  EXPECT_EQ(LexiconParts("walk without moving the arms"), G | LL | RL);
  EXPECT_EQ(LexiconParts("jog with arms still"), G | LL | RL);
  EXPECT_EQ(LexiconParts("bend knees"), LL | RL);
  EXPECT_EQ(LexiconParts("look around"), T);
  EXPECT_EQ(LexiconParts("hands on hips"), G | LA | RA);
  EXPECT_EQ(LexiconParts("a person does jumping jacks"), G | T | LA | RA | LL | RL);
  EXPECT_EQ(LexiconParts("punch right"), T | RA);
  EXPECT_EQ(LexiconParts("turn left"), T);
}

TEST(Labels, ScoringIgnoresSometimes) {
  std::vector<LabelledText> truth(2);
  truth[0].truth = {1, 0, 0.5f, 0.5f, 1, 1};  // walk: arms "sometimes"
  truth[1].truth = {0, 0, 1, 0, 0, 0};
  const PartSet G = PartBit(BodyPart::kGlobal), LL = PartBit(BodyPart::kLeftLeg),
                RL = PartBit(BodyPart::kRightLeg), LA = PartBit(BodyPart::kLeftArm),
                RA = PartBit(BodyPart::kRightArm);
  const LabelerAccuracy acc =
      ScoreLabels(truth, {static_cast<PartSet>(G | LL | RL | LA), static_cast<PartSet>(LA | RA)});
  EXPECT_EQ(acc.counted[2], 1);        // the left arm of "walk" is not counted
  EXPECT_DOUBLE_EQ(acc.part[2], 1.0);  // text 2's left arm right
  EXPECT_DOUBLE_EQ(acc.part[3], 0.0);  // text 2's right arm wrong
  EXPECT_DOUBLE_EQ(acc.part[0], 1.0);
  EXPECT_NEAR(acc.mean, 5.0 / 6.0, 1e-12);
}

TEST(Labels, HeldOutSplitIsStable) {
  int held = 0;
  for (int k = 0; k < 1000; ++k) held += IsHeldOut("text " + std::to_string(k)) ? 1 : 0;
  EXPECT_GT(held, 150);
  EXPECT_LT(held, 250);
  EXPECT_EQ(IsHeldOut("walk forward"), IsHeldOut("walk forward"));
}

}  // namespace
}  // namespace motionpipe::labels
