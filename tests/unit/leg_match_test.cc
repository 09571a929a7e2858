#include "motionpipe/motion/leg_match.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "motionpipe/base/random.h"
#include "motionpipe/corpus/script.h"
#include "motionpipe/corpus/synthesizer.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/foot_lock.h"
#include "motionpipe/motion/plausibility.h"

namespace motionpipe {
namespace {

using corpus::ActionId;

const Skeleton& Smpl() { return Skeleton::Smpl22(); }

constexpr int kLegJoints[] = {1, 4, 7, 10, 2, 5, 8, 11};  // hips, knees, ankles, toes

bool IsLeg(int joint) {
  for (int j : kLegJoints)
    if (j == joint) return true;
  return false;
}

// A procedural walk of `seconds` (the corpus's synthesizer: its feet are planted by construction).
Motion Walk(uint64_t seed, double seconds) {
  Rng rng(seed);
  corpus::ClipScript script;
  script.style = corpus::SampleStyle(rng);
  corpus::ActionInstance walk = corpus::SampleInstance(ActionId::kWalk, rng);
  walk.start = 0;
  walk.end = seconds;
  script.base = {walk};
  script.duration = seconds;
  return corpus::Synthesize(script, Smpl()).motion;
}

// The motion with every leg joint held at its mean local rotation (legs that do not step while
// the pelvis travels: SINC's generations).
Motion StillLegs(const Motion& motion) {
  Motion out = motion;
  const int64_t frames = motion.num_frames();
  for (int joint : kLegJoints) {
    Vec3 sum{0, 0, 0};
    for (int64_t f = 0; f < frames; ++f)
      sum = sum + MatrixToAxisAngle(motion.LocalRotation(f, joint));
    const Mat3 mean = AxisAngleToMatrix((1.0 / static_cast<double>(frames)) * sum);
    for (int64_t f = 0; f < frames; ++f) out.SetLocalRotation(f, joint, mean);
  }
  return out;
}

double KneeSwingDegrees(const Motion& motion) {
  double sum = 0, square = 0;
  const int64_t frames = motion.num_frames();
  for (int64_t f = 0; f < frames; ++f) {
    const Mat3 r = motion.LocalRotation(f, 4);
    const double angle =
        std::acos(std::clamp((r.m[0][0] + r.m[1][1] + r.m[2][2] - 1) / 2, -1.0, 1.0)) * 180 / M_PI;
    sum += angle;
    square += angle * angle;
  }
  const double mean = sum / static_cast<double>(frames);
  return std::sqrt(std::max(square / static_cast<double>(frames) - mean * mean, 0.0));
}

LegDatabase Database(const std::vector<Motion>& motions, const LegMatchOptions& options = {}) {
  LegDatabase db(Smpl(), options);
  for (size_t i = 0; i < motions.size(); ++i) {
    const Status s = db.Add(motions[i], "walk " + std::to_string(i));
    EXPECT_TRUE(s.ok()) << s.message();
  }
  return db;
}

std::vector<Motion> Walks(int count) {
  std::vector<Motion> walks;
  for (int i = 0; i < count; ++i) walks.push_back(Walk(100 + static_cast<uint64_t>(i), 4.0));
  return walks;
}

TEST(LegMatch, AWindowOfTheDatabaseIsItsOwnNearestAndKeepsItsLegs) {
  const std::vector<Motion> walks = Walks(4);
  LegDatabase db = Database(walks);
  EXPECT_EQ(db.motions(), 4);
  EXPECT_EQ(db.frames(), 4 * walks[0].num_frames());
  // Frames [30, 90) of the third walk: a window the database compares (starts every 3 frames).
  const Motion window = SliceFrames(walks[2], 30, 90);
  LegMatchReport report;
  auto matched = db.Match(window, &report);
  ASSERT_TRUE(matched.ok()) << matched.status().message();
  EXPECT_EQ(report.matched, 1);
  EXPECT_NEAR(report.MeanDegrees(), 0.0, 1e-3);
  for (size_t k = 0; k < window.poses.size(); ++k)
    EXPECT_FLOAT_EQ(matched->poses[k], window.poses[k]);
  // Its legs made still, the window is found again by its pelvis path: its own legs come back.
  LegMatchReport still_report;
  auto restored = db.Match(StillLegs(window), &still_report);
  ASSERT_TRUE(restored.ok());
  EXPECT_GT(still_report.MeanDegrees(), 1.0);
  // (The copy's cost is not 0: its end frames lack the neighbours that its velocity and low-pass
  // read inside the walk. Still legs are farther.)
  EXPECT_GT(still_report.MeanCost(), report.MeanCost());
  for (int64_t f = 0; f < window.num_frames(); ++f)
    for (int joint : kLegJoints)
      EXPECT_LT(MaxAbsDiff(restored->LocalRotation(f, joint), window.LocalRotation(f, joint)), 1e-5)
          << "frame " << f << " joint " << joint;
}

TEST(LegMatch, AWalkItNeverSawIsGivenAGaitAndOnlyItsLegsChange) {
  // The legs of a walk the database does not hold, made still: its pelvis glides, as SINC's do.
  LegDatabase db = Database(Walks(6));
  const Motion walk = SliceFrames(Walk(7, 4.0), 0, 90);
  const Motion still = StillLegs(walk);
  auto matched = db.Match(still);
  ASSERT_TRUE(matched.ok()) << matched.status().message();
  // Every joint but the legs', and the pelvis path, are the motion's own.
  for (int64_t f = 0; f < still.num_frames(); ++f) {
    for (int joint = 0; joint < kNumJoints; ++joint) {
      if (!IsLeg(joint)) {
        EXPECT_EQ(MaxAbsDiff(matched->LocalRotation(f, joint), still.LocalRotation(f, joint)), 0.0);
      }
    }
    EXPECT_EQ(Norm(matched->Translation(f) - still.Translation(f)), 0.0);
  }
  // The knees swing again (the still legs': 0), and once planted the feet slide far less than the
  // still legs' planted.
  EXPECT_GT(KneeSwingDegrees(*matched), 0.5 * KneeSwingDegrees(walk));
  const double still_skate =
      EvaluateMotionPlausibility(Smpl(), LockFeet(Smpl(), still)).foot_skate_ratio;
  const double matched_skate =
      EvaluateMotionPlausibility(Smpl(), LockFeet(Smpl(), *matched)).foot_skate_ratio;
  EXPECT_GT(still_skate, 0.3);
  EXPECT_LT(matched_skate, 0.5 * still_skate);
}

TEST(LegMatch, MatchedPelvisKeepsTheHeadingAndPathAndTakesTheHeight) {
  const std::vector<Motion> walks = Walks(3);
  LegMatchOptions options;
  options.match_pelvis = true;
  LegDatabase db = Database(walks, options);
  Motion window = SliceFrames(walks[1], 30, 90);
  Motion turned = window;  // the same window, a quarter turn about z and 5 cm higher
  for (int64_t f = 0; f < turned.num_frames(); ++f) {
    turned.SetLocalRotation(f, 0, RotZ(M_PI / 2) * window.LocalRotation(f, 0));
    const Vec3 p = window.Translation(f);
    turned.SetTranslation(f, {-p.y, p.x, p.z + 0.05});
  }
  auto matched = db.Match(turned);
  ASSERT_TRUE(matched.ok());
  for (int64_t f = 0; f < turned.num_frames(); ++f) {
    EXPECT_NEAR(std::remainder(HeadingZYX(matched->LocalRotation(f, 0)) -
                                   HeadingZYX(turned.LocalRotation(f, 0)),
                               2 * M_PI),
                0.0, 1e-5);
    EXPECT_LT(MaxAbsDiff(RemoveHeading(matched->LocalRotation(f, 0)),
                         RemoveHeading(window.LocalRotation(f, 0))),
              1e-5);
    EXPECT_DOUBLE_EQ(matched->Translation(f).x, turned.Translation(f).x);
    EXPECT_NEAR(matched->Translation(f).z, window.Translation(f).z, 1e-6);
  }
}

TEST(LegMatch, TheRandomControlDrawsReproducibleWindowsOfTheDatabase) {
  const std::vector<Motion> walks = Walks(4);
  LegMatchOptions options;
  options.random = true;
  options.seed = 3;
  LegDatabase a = Database(walks, options), b = Database(walks, options);
  const Motion window = SliceFrames(walks[0], 0, 60);
  LegMatchReport report;
  auto first = a.Match(window, &report), again = b.Match(window);
  ASSERT_TRUE(first.ok() && again.ok());
  EXPECT_EQ(first->poses, again->poses);  // the same seed, the same draw
  EXPECT_EQ(report.matched, 1);
  auto second = a.Match(window);  // the next draw
  ASSERT_TRUE(second.ok());
  EXPECT_NE(first->poses, second->poses);
}

TEST(LegMatch, RefusesWhatItCannotMatch) {
  const std::vector<Motion> walks = Walks(2);
  LegDatabase empty(Smpl(), {});
  EXPECT_EQ(empty.Match(walks[0]).status().code(), StatusCode::kFailedPrecondition);
  LegDatabase db = Database(walks);
  Motion other_rate = walks[0];
  other_rate.fps = 20;
  const Status late_rate = db.Add(other_rate, "clip 7");
  EXPECT_EQ(late_rate.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(late_rate.message().find("clip 7"), std::string::npos) << late_rate.message();
  EXPECT_EQ(db.Match(other_rate).status().code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE(db.Match(walks[0]).ok());
  EXPECT_EQ(db.Add(walks[0], "walk 0").code(), StatusCode::kFailedPrecondition);
}

TEST(LegMatch, AMotionLongerThanTheDatabasesIsMatchedInBlendedWindows) {
  // 2-s walks in the database; a 6-s walk it never saw, with still legs.
  std::vector<Motion> walks;
  for (int i = 0; i < 8; ++i) walks.push_back(Walk(200 + static_cast<uint64_t>(i), 2.0));
  LegDatabase db = Database(walks);
  const Motion walk = Walk(11, 6.0);
  const Motion still = StillLegs(walk);
  LegMatchReport report;
  auto matched = db.Match(still, &report);
  ASSERT_TRUE(matched.ok()) << matched.status().message();
  EXPECT_EQ(report.matched, 1);
  EXPECT_GE(report.windows, 5);  // 180 frames in windows of 60, each 30 after the last
  EXPECT_EQ(matched->num_frames(), still.num_frames());
  EXPECT_EQ(matched->trans, still.trans);
  // The legs step over the whole motion, and where the windows meet they are blended: planted, the
  // feet slide on under 45% of the still legs' planted skate (0.36 against 0.89 here; with each
  // window written over the last, unblended, 0.45).
  EXPECT_GT(KneeSwingDegrees(SliceFrames(*matched, 0, 90)), 0.5 * KneeSwingDegrees(walk));
  EXPECT_GT(KneeSwingDegrees(SliceFrames(*matched, 90, 180)), 0.5 * KneeSwingDegrees(walk));
  const double still_skate =
      EvaluateMotionPlausibility(Smpl(), LockFeet(Smpl(), still)).foot_skate_ratio;
  EXPECT_LT(EvaluateMotionPlausibility(Smpl(), LockFeet(Smpl(), *matched)).foot_skate_ratio,
            0.45 * still_skate);
}

// Triplet files read several at once fill the database as adding each side in the files' and
// rows' order does: the same frames and the same matches to the bit; `limit` counts triplets over
// the files; a bad file is named, and one past the limit is never taken.
TEST(LegMatch, TripletFilesFillTheDatabaseAsAddingEachSideInOrder) {
  const std::string dir = ::testing::TempDir() + "/leg_match_triplet_files";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::vector<std::string> files;
  uint64_t seed = 300;
  for (int f = 0; f < 5; ++f) {
    std::vector<Triplet> triplets(3);
    for (size_t k = 0; k < triplets.size(); ++k) {
      Triplet& t = triplets[k];
      t.id = "f" + std::to_string(f) + "t" + std::to_string(k);
      t.text = "walk";
      t.split = (f == 2 || k == 1) ? "test" : "train";  // file 2 holds no training triplet
      t.source = Walk(seed++, 2.0 + 0.5 * static_cast<double>(k));
      t.target = Walk(seed++, 3.0);
    }
    files.push_back(dir + "/triplets-" + std::to_string(f) + ".npz");
    ASSERT_TRUE(WriteTriplets(files.back(), triplets).ok());
  }
  const auto identity = [](const Motion& motion) { return motion; };
  const Motion query = StillLegs(SliceFrames(Walk(9, 4.0), 0, 90));
  const auto matched = [&](LegDatabase& db) {
    LegMatchReport report;
    auto out = db.Match(query, &report);
    EXPECT_TRUE(out.ok()) << out.status().message();
    return std::make_pair(out.ok() ? out->poses : std::vector<float>{}, report.cost);
  };
  LegMatchOptions drawn;  // the random control numbers the windows in the database's order
  drawn.random = true;
  for (const auto& [limit, options] :
       {std::pair{int64_t{0}, LegMatchOptions{}}, std::pair{int64_t{3}, LegMatchOptions{}},
        std::pair{int64_t{0}, drawn}}) {
    LegDatabase one_by_one(Smpl(), options);
    int64_t visited = 0;
    for (const std::string& file : files) {
      if (limit > 0 && visited >= limit) break;
      auto n = VisitTripletSides(file, "train", limit > 0 ? limit - visited : 0,
                                 [&](const Motion& motion, const std::string& origin) {
                                   return one_by_one.Add(motion, origin);
                                 });
      ASSERT_TRUE(n.ok()) << n.status().message();
      visited += *n;
    }
    LegDatabase at_once(Smpl(), options);
    auto added = AddTripletSides(files, "train", limit, identity, &at_once);
    ASSERT_TRUE(added.ok()) << added.status().message();
    EXPECT_EQ(*added, limit > 0 ? limit : 8);  // 2 training triplets in 4 of the files
    EXPECT_EQ(*added, visited);
    EXPECT_EQ(at_once.motions(), 2 * visited);
    EXPECT_EQ(at_once.frames(), one_by_one.frames());
    const auto a = matched(one_by_one), b = matched(at_once);
    EXPECT_EQ(a.second, b.second) << "limit " << limit << ", random " << options.random;
    EXPECT_EQ(a.first, b.first) << "limit " << limit << ", random " << options.random;
  }
  // A file that is not a triplets file, third in the list: named; past a limit reached by the
  // first file, never taken.
  {
    std::ofstream bad(dir + "/triplets-bad.npz");
    bad << "not a zip archive";
  }
  std::vector<std::string> with_bad = files;
  with_bad.insert(with_bad.begin() + 2, dir + "/triplets-bad.npz");
  LegDatabase refused(Smpl(), {});
  auto error = AddTripletSides(with_bad, "train", 0, identity, &refused);
  ASSERT_FALSE(error.ok());
  EXPECT_NE(error.status().message().find("triplets-bad.npz"), std::string::npos)
      << error.status().message();
  EXPECT_EQ(refused.motions(), 8);  // both sides of the two files' 2 training triplets before it
  LegDatabase limited(Smpl(), {});
  auto within = AddTripletSides(with_bad, "train", 2, identity, &limited);
  ASSERT_TRUE(within.ok()) << within.status().message();
  EXPECT_EQ(*within, 2);
  // A side the database refuses is named by file, triplet and side: here every 2-s source is
  // given another rate, so the first side sets 20 fps and the next, at 30, is refused.
  LegDatabase rates(Smpl(), {});
  auto refused_rate = AddTripletSides(
      files, "train", 0,
      [](const Motion& motion) {
        Motion m = motion;
        if (m.num_frames() == 60) m.fps = 20;
        return m;
      },
      &rates);
  ASSERT_FALSE(refused_rate.ok());
  EXPECT_NE(refused_rate.status().message().find("triplets-0.npz, triplet 'f0t0' (target)"),
            std::string::npos)
      << refused_rate.status().message();
  std::filesystem::remove_all(dir);
}

TEST(LegMatch, OptionsAreReadWithTheirKeysAndChecked) {
  auto parsed = LegMatchOptionsFromJson(
      {{"sigma_seconds", 0.5}, {"match_pelvis", true}, {"motions", "x"}}, "p", {"motions"});
  ASSERT_TRUE(parsed.ok()) << parsed.status().message();
  EXPECT_EQ(parsed->sigma_seconds, 0.5);
  EXPECT_TRUE(parsed->match_pelvis);
  EXPECT_EQ(LegMatchOptionsToJson(*parsed)["sigma_seconds"], 0.5);
  auto unknown = LegMatchOptionsFromJson({{"sigma", 0.5}}, "p");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("p.sigma: unknown"), std::string::npos);
  EXPECT_FALSE(LegMatchOptionsFromJson({{"frame_step", 0}}, "p").ok());
  EXPECT_FALSE(LegMatchOptionsFromJson({{"legs_weight", -1}}, "p").ok());
  EXPECT_FALSE(LegMatchOptionsFromJson({{"random", "yes"}}, "p").ok());
}

}  // namespace
}  // namespace motionpipe
