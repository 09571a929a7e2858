// The leg clean-up (plugins/leg_cleanup): its rotations, kinematics and heading-free input, the
// corruption, an untrained net giving the legs back, the loss, a few steps that learn, and its
// refusals.
#include "../../plugins/leg_cleanup/leg_cleanup.h"

#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "motionpipe/base/file.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::legs {
namespace {

// A turning, swinging walk at 30 fps: legs swing, every joint jitters a little.
Motion Walk(int64_t frames, uint64_t seed = 0) {
  Motion m = Motion::Rest(frames, 30, 0.9);
  auto generator = at::make_generator<at::CPUGeneratorImpl>(seed);
  const auto jitter = 0.05 * torch::randn({frames, kNumJoints, 3}, generator);
  for (int64_t f = 0; f < frames; ++f) {
    const double t = static_cast<double>(f) / 30;
    for (int j = 0; j < kNumJoints; ++j) {
      for (int c = 0; c < 3; ++c)
        m.poses[static_cast<size_t>((f * kNumJoints + j) * 3 + c)] = jitter[f][j][c].item<float>();
    }
    m.poses[static_cast<size_t>(f * kNumJoints * 3)] = static_cast<float>(M_PI / 2);
    m.poses[static_cast<size_t>(f * kNumJoints * 3 + 1)] = 0;
    m.poses[static_cast<size_t>(f * kNumJoints * 3 + 2)] = static_cast<float>(0.3 * t);  // turning
    m.poses[static_cast<size_t>((f * kNumJoints + 1) * 3)] +=
        static_cast<float>(0.5 * std::sin(2 * M_PI * t));
    m.poses[static_cast<size_t>((f * kNumJoints + 2) * 3)] -=
        static_cast<float>(0.5 * std::sin(2 * M_PI * t));
    m.SetTranslation(f, {std::cos(t), std::sin(t), 0.9 + 0.02 * std::sin(4 * t)});
  }
  return m;
}

// [1, T, 22, 3, 3] local rotations and [1, T, 3] pelvis of a motion.
std::pair<torch::Tensor, torch::Tensor> Tensors(const Motion& m) {
  const int64_t t = m.num_frames();
  auto poses = torch::from_blob(const_cast<float*>(m.poses.data()), {1, t, kNumJoints, 3}).clone();
  auto trans = torch::from_blob(const_cast<float*>(m.trans.data()), {1, t, 3}).clone();
  return {Rodrigues(poses), trans};
}

torch::Tensor Legs(const torch::Tensor& r) {
  return torch::stack({r.select(2, 1), r.select(2, 2), r.select(2, 4), r.select(2, 5),
                       r.select(2, 7), r.select(2, 8)},
                      2);
}

TEST(LegCleanup, RotationsRoundTrip) {
  auto generator = at::make_generator<at::CPUGeneratorImpl>(3);
  const auto v = 0.9 * torch::randn({50, 3}, generator).clamp(-1.5, 1.5);
  const auto r = Rodrigues(v);
  EXPECT_LT((torch::matmul(r, r.transpose(-1, -2)) - torch::eye(3)).abs().max().item<double>(),
            1e-5);
  EXPECT_LT((LogMap(r) - v).abs().max().item<double>(), 1e-3);
  EXPECT_LT((FromSixD(SixD(r)) - r).abs().max().item<double>(), 1e-5);
  // The identity: no angle, no NaN.
  EXPECT_LT((Rodrigues(torch::zeros({1, 3})) - torch::eye(3)).abs().max().item<double>(), 1e-7);
}

// The shared 6D helpers (plugins/common/kinematics.h): by rows they are core's Rot6d (the MotionFix
// features the editors' foot losses read), by columns the transposed matrix's (the clean-up's
// inputs); the leg chains are the skeleton's, hip to foot, each joint the child of the one before.
TEST(LegCleanup, SharedSixDAndLegChainsFollowTheCore) {
  auto generator = at::make_generator<at::CPUGeneratorImpl>(5);
  const auto r = Rodrigues(torch::randn({20, 3}, generator).to(torch::kFloat64));
  const auto rows = nn::MatrixToSixD(r, nn::SixDAxes::kRows);
  const auto columns = nn::MatrixToSixD(r, nn::SixDAxes::kColumns);
  EXPECT_LT((columns - nn::MatrixToSixD(r.transpose(-1, -2), nn::SixDAxes::kRows))
                .abs()
                .max()
                .item<double>(),
            1e-12);
  // Not orthonormal: the Gram-Schmidt has work to do.
  const auto six = rows + 0.3 * torch::randn({20, 6}, generator).to(torch::kFloat64);
  const auto by_rows = nn::SixDToMatrix(six, nn::SixDAxes::kRows);
  const auto by_columns = nn::SixDToMatrix(six, nn::SixDAxes::kColumns);
  EXPECT_LT((by_columns - by_rows.transpose(-1, -2)).abs().max().item<double>(), 1e-12);
  for (int64_t i = 0; i < 20; ++i) {
    Mat3 m;
    Rot6d given;
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) m[a][b] = r[i][a][b].item<double>();
    }
    for (int k = 0; k < 6; ++k) given[static_cast<size_t>(k)] = six[i][k].item<double>();
    const Rot6d core_six = MatrixToRot6d(m);
    const Mat3 core_matrix = Rot6dToMatrix(given);
    for (int k = 0; k < 6; ++k)
      EXPECT_NEAR(rows[i][k].item<double>(), core_six[static_cast<size_t>(k)], 1e-12);
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b)
        EXPECT_NEAR(by_rows[i][a][b].item<double>(), core_matrix[a][b], 1e-9);
    }
  }
  const Skeleton& skeleton = Skeleton::Smpl22();
  const auto chains = nn::LegChains(skeleton);
  EXPECT_EQ(chains[0], (std::array<int, 4>{1, 4, 7, 10}));
  EXPECT_EQ(chains[1], (std::array<int, 4>{2, 5, 8, 11}));
  for (const auto& chain : chains) {
    EXPECT_EQ(skeleton.parents()[static_cast<size_t>(chain[0])], 0);
    for (size_t k = 1; k < chain.size(); ++k)
      EXPECT_EQ(skeleton.parents()[static_cast<size_t>(chain[k])], chain[k - 1]);
    // The clean-up's joints are each chain's hip, knee and ankle.
    for (size_t k = 0; k < 3; ++k)
      EXPECT_NE(std::find(kLegJoints.begin(), kLegJoints.end(), chain[k]), kLegJoints.end());
  }
  // A skeleton file that lists a side's foot joints toe first gives the same chains; foot joints
  // off the legs' chains are refused, naming them.
  auto text = ReadFile(MOTIONPIPE_DATA_DIR "/skeleton/smpl22.json");
  ASSERT_TRUE(text.ok());
  auto doc = nlohmann::json::parse(*text);
  doc["feet_joints"] = {{"left", {10, 7}}, {"right", {11, 8}}};
  auto swapped = Skeleton::FromJson(doc.dump(), "swapped.json");
  ASSERT_TRUE(swapped.ok()) << swapped.status().message();
  EXPECT_EQ(nn::LegChains(*swapped), chains);
  doc["feet_joints"] = {{"left", {7, 10}}, {"right", {20, 21}}};  // the wrists
  auto wrists = Skeleton::FromJson(doc.dump(), "wrists.json");
  ASSERT_TRUE(wrists.ok()) << wrists.status().message();
  try {
    nn::LegChains(*wrists);
    ADD_FAILURE() << "foot joints on the arms were taken for legs";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("foot joints 20 and 21"), std::string::npos) << e.what();
  }
}

TEST(LegCleanup, ForwardKinematicsAgreeWithTheCore) {
  const Motion m = Walk(12);
  const auto [r, trans] = Tensors(m);
  const auto ours = LegPositions(trans, r.select(2, 0), Legs(r))[0];  // [T, 6, 3]
  const std::vector<float> joints = ComputeJoints(Skeleton::Smpl22(), m);
  const int order[6] = {4, 7, 10, 5, 8, 11};  // knee, ankle, foot of the left leg, then the right
  for (int64_t f = 0; f < 12; ++f) {
    for (int k = 0; k < 6; ++k) {
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(ours[f][k][c].item<double>(),
                    joints[static_cast<size_t>((f * kNumJoints + order[k]) * 3 + c)], 1e-4)
            << "frame " << f << " joint " << order[k];
    }
  }
}

TEST(LegCleanup, RootFeaturesDoNotSeeTheHeading) {
  const Motion m = Walk(20);
  const auto [r, trans] = Tensors(m);
  const auto a = RootFeatures(trans, r.select(2, 0), 30);
  // The whole motion turned 70 degrees about the vertical and moved: the same features.
  const double angle = 70 * M_PI / 180;
  const auto yaw = torch::tensor({std::cos(angle), -std::sin(angle), 0.0, std::sin(angle),
                                  std::cos(angle), 0.0, 0.0, 0.0, 1.0},
                                 torch::kFloat32)
                       .reshape({3, 3});
  const auto turned_trans =
      torch::matmul(yaw, trans.unsqueeze(-1)).squeeze(-1) + torch::tensor({5.f, -2.f, 0.f});
  const auto b = RootFeatures(turned_trans, torch::matmul(yaw, r.select(2, 0)), 30);
  EXPECT_EQ(a.sizes(), (std::vector<int64_t>{1, 20, kRootFeatures}));
  EXPECT_LT((a - b).abs().max().item<double>(), 1e-3);
  // The height is the pelvis's; the speed the walk's (1 m/s along a circle of radius 1).
  EXPECT_NEAR(a[0][3][0].item<double>(), m.trans[3 * 3 + 2], 1e-6);
  EXPECT_NEAR(a[0][5].narrow(0, 1, 3).norm().item<double>(), 1.0, 0.05);
}

TEST(LegCleanup, CorruptionIsBoundedAndDoesWhatItSays) {
  const Motion m = Walk(60);
  const auto [r, trans] = Tensors(m);
  const auto legs = Legs(r);
  CleanupOptions none;
  none.degrees = 0, none.toward_share = 0, none.warp_share = 0, none.shrink = 0;
  auto generator = at::make_generator<at::CPUGeneratorImpl>(1);
  EXPECT_LT((Corrupt(legs, legs, none, generator) - legs).abs().max().item<double>(), 1e-5);
  // A still pose: warping its timing or shrinking its swing changes nothing.
  const auto still = legs.narrow(1, 0, 1).expand_as(legs).contiguous();
  CleanupOptions reshape = none;
  reshape.warp_share = 1, reshape.shrink = 1;
  EXPECT_LT((Corrupt(still, still, reshape, generator) - still).abs().max().item<double>(), 1e-5);
  // Shrunk, the swing about the window's mean narrows.
  CleanupOptions shrink = none;
  shrink.shrink = 1;
  const auto spread = [](const torch::Tensor& x) {
    const auto six = SixD(x);
    return (six - six.mean(1, true)).pow(2).mean().item<double>();
  };
  EXPECT_LT(spread(Corrupt(legs, legs, shrink, generator)), spread(legs));
  CleanupOptions noisy = none;
  noisy.degrees = 1;
  const auto angle =
      LogMap(torch::matmul(legs.transpose(-1, -2), Corrupt(legs, legs, noisy, generator)))
          .norm(2, -1);
  // Key noise of spread up to 1 degree and a slow offset up to 3: a few degrees on average.
  EXPECT_GT(angle.max().item<double>(), 0);
  EXPECT_LT(angle.mean().item<double>(), 6 * M_PI / 180);
  EXPECT_LT(angle.max().item<double>(), 25 * M_PI / 180);
  // The partner drawn in by up to `toward`: never further than the partner.
  CleanupOptions toward = none;
  toward.toward_share = 1;
  const auto partner = legs.flip(1).contiguous();
  const auto moved = Corrupt(legs, partner, toward, generator);
  const auto to_partner = LogMap(torch::matmul(legs.transpose(-1, -2), partner)).norm(2, -1);
  const auto moved_by = LogMap(torch::matmul(legs.transpose(-1, -2), moved)).norm(2, -1);
  EXPECT_LE((moved_by - 0.4 * to_partner).max().item<double>(), 1e-3);
  // The height error: offset, drift and wobble within 5 + 7.5 cm + 5 cm per unit of wobble.
  const auto drift = HeightDrift(64, 60, generator);
  EXPECT_EQ(drift.sizes(), (std::vector<int64_t>{64, 60}));
  EXPECT_LT(drift.abs().max().item<double>(), 0.5);
  EXPECT_GT(drift.abs().max().item<double>(), 0.01);
}

TEST(LegCleanup, AnUntrainedNetGivesTheMotionBack) {
  CleanupOptions options;
  options.width = 16;
  options.height = true;
  CleanupNet net(options);
  const Motion m = Walk(40);
  auto cleaned = CleanLegs(net, options, m);
  ASSERT_TRUE(cleaned.ok()) << cleaned.status().message();
  ASSERT_EQ(cleaned->num_frames(), 40);
  for (int64_t f = 0; f < 40; ++f) {
    for (int j = 0; j < kNumJoints; ++j) {
      const bool leg = j == 1 || j == 2 || j == 4 || j == 5 || j == 7 || j == 8;
      for (int c = 0; c < 3; ++c) {
        const size_t i = static_cast<size_t>((f * kNumJoints + j) * 3 + c);
        if (leg) {
          EXPECT_NEAR(cleaned->poses[i], m.poses[i], 1e-5);
        } else {
          EXPECT_EQ(cleaned->poses[i], m.poses[i]);
        }
      }
    }
  }
  EXPECT_EQ(cleaned->trans, m.trans);
  // Too short to clean: as it was; at another rate: refused, naming both rates.
  const Motion short_motion = Walk(5);
  EXPECT_EQ(CleanLegs(net, options, short_motion)->poses, short_motion.poses);
  Motion slow = m;
  slow.fps = 20;
  auto refused = CleanLegs(net, options, slow);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("20"), std::string::npos);
  EXPECT_NE(refused.status().message().find("trained at 30"), std::string::npos);
}

TEST(LegCleanup, TheLossIsZeroOnCleanLegsAndFallsWithTraining) {
  torch::manual_seed(0);
  CleanupOptions options;
  options.width = 32;
  options.dilations = {1, 2};
  CleanupNet net(options);
  const Motion m = Walk(60, 4);
  const auto [r, trans] = Tensors(m);
  Window w;
  w.trans = trans, w.given_trans = trans, w.r0 = r.select(2, 0), w.legs = Legs(r);
  w.noisy = w.legs;
  auto clean = CleanupLosses(net, w, options);
  EXPECT_LT(clean["rotation"].item<double>(), 1e-10);
  EXPECT_LT(clean["position"].item<double>(), 1e-10);
  // Legs that carry a fixed offset: a few steps on them take most of it away.
  auto generator = at::make_generator<at::CPUGeneratorImpl>(2);
  w.noisy = torch::matmul(w.legs, Rodrigues(0.1 * torch::randn({1, 1, 6, 3}, generator)));
  torch::optim::Adam adam(net->parameters(), torch::optim::AdamOptions(1e-3));
  const double before = CleanupLosses(net, w, options)["loss"].item<double>();
  for (int step = 0; step < 60; ++step) {
    adam.zero_grad();
    CleanupLosses(net, w, options)["loss"].backward();
    adam.step();
  }
  const double after = CleanupLosses(net, w, options)["loss"].item<double>();
  EXPECT_LT(after, 0.2 * before) << before << " -> " << after;
}

// A dataset the options and data context cannot make: refused with a message holding `why`.
void ExpectRefused(const CleanupOptions& options, const plugin::DataContext& context,
                   const std::string& why) {
  try {
    CleanupDataset refused(options, context);
    ADD_FAILURE() << context.config.dump() << " was read (" << why << ")";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
  }
}

// A triplets directory: `rows` triplets of 60-frame walks in `split` (the last of them 20 frames
// long, too short for a 40-frame crop) at `fps`.
std::string WriteTriplets(const std::string& name, int rows, const std::string& split,
                          double fps = 30) {
  const std::string dir = ::testing::TempDir() + "/" + name;
  std::filesystem::create_directories(dir + "/motionfix");
  std::vector<Triplet> triplets;
  for (int i = 0; i < rows; ++i) {
    Triplet t;
    t.id = name + std::to_string(i);
    t.text = "walk faster";
    t.split = i == 0 ? "val" : split;
    const int64_t frames = i == rows - 1 ? 20 : 60;
    t.source = Walk(frames, static_cast<uint64_t>(2 * i));
    t.target = Walk(frames, static_cast<uint64_t>(2 * i + 1));
    t.source.fps = t.target.fps = fps;
    triplets.push_back(std::move(t));
  }
  EXPECT_TRUE(motionpipe::WriteTriplets(dir + "/motionfix/triplets-00000.npz", triplets).ok());
  return dir;
}

TEST(LegCleanup, DatasetCropsBothSidesAndRefusesWhatItCannotUse) {
  CleanupOptions options;
  options.crop = 40;
  options.height = true;
  plugin::DataContext context;
  context.input_dirs = {WriteTriplets("cleanup_data", 4, "train")};
  // Triplets 1 and 2 of the train split, both sides; the 20-frame triplet 3 is too short.
  CleanupDataset train(options, context);
  EXPECT_EQ(train.size(), 4);
  context.split = "val";
  EXPECT_EQ(CleanupDataset(options, context).size(), 2);
  context.split = "train";
  const auto a = train.Get({0, 3, 1}, 7), b = train.Get({0, 3, 1}, 7), c = train.Get({0, 3, 1}, 8);
  EXPECT_EQ(a.size, 3);
  EXPECT_EQ(a.tensors.at("legs").sizes(), (std::vector<int64_t>{3, 40, 6, 3, 3}));
  EXPECT_EQ(a.tensors.at("r0").sizes(), (std::vector<int64_t>{3, 40, 3, 3}));
  for (const char* name : {"trans", "given_trans", "r0", "legs", "noisy"}) {
    EXPECT_TRUE(torch::equal(a.tensors.at(name), b.tensors.at(name))) << name;
  }
  EXPECT_FALSE(torch::equal(a.tensors.at("noisy"), c.tensors.at("noisy")));
  // Only the height of the pelvis is drifted; the crop is a motion's own frames (rotations).
  const auto drift = a.tensors.at("given_trans") - a.tensors.at("trans");
  EXPECT_EQ(drift.narrow(-1, 0, 2).abs().max().item<double>(), 0);
  EXPECT_GT(drift.select(-1, 2).abs().max().item<double>(), 0);
  const auto legs = a.tensors.at("legs");
  EXPECT_LT(
      (torch::matmul(legs, legs.transpose(-1, -2)) - torch::eye(3)).abs().max().item<double>(),
      1e-5);
  // data.triplets instead of the inputs; then nothing, another rate, only short motions: refused
  // with the directory, file or triplet named.
  plugin::DataContext given;
  given.config = {{"triplets", context.input_dirs[0]}};
  EXPECT_EQ(CleanupDataset(options, given).size(), 4);
  given.config = {{"triplets", ::testing::TempDir() + "/nowhere"}};
  ExpectRefused(options, given, "nowhere");
  plugin::DataContext slow;
  slow.input_dirs = {WriteTriplets("cleanup_20fps", 3, "train", 20)};
  ExpectRefused(options, slow, "triplets-00000.npz: triplet cleanup_20fps1 at 20 fps");
  options.crop = 80;
  ExpectRefused(options, context, "no motions of 80 frames or more in split 'train'");
}

// A motion whose pelvis walks 1 cm a frame along x, so that a window tells which frames it took.
Motion Ramp(int64_t frames, double fps) {
  Motion m = Motion::Rest(frames, fps, 0.9);
  for (int64_t f = 0; f < frames; ++f) m.SetTranslation(f, {0.01 * static_cast<double>(f), 0, 0.9});
  return m;
}

// Motion files (real mocap: clips, AMASS npz, BVH) instead of triplets: resampled to the trained
// rate, the last val_fraction of each motion held out, refusals naming what is wrong.
TEST(LegCleanup, DatasetReadsMotionFilesAndHoldsOutEachOnesEnd) {
  const std::string dir = ::testing::TempDir() + "/cleanup_motions";
  std::filesystem::create_directories(dir);
  std::vector<Clip> clips(3);
  clips[0].id = "ramp60";
  clips[0].motion = Ramp(200, 60);  // 100 frames at 30 fps
  clips[1].id = "walk";
  clips[1].motion = Walk(90);
  clips[2].id = "short";
  clips[2].motion = Walk(20);
  ASSERT_TRUE(WriteClips(dir + "/clips.npz", clips).ok());
  CleanupOptions options;
  options.crop = 40;
  plugin::DataContext train;
  train.config = {{"motions", dir}, {"val_fraction", 0.5}};
  plugin::DataContext val = train;
  val.split = "val";
  // Each of the two long motions gives a track to either part; the short one to neither.
  CleanupDataset from_dir(options, train), held_out(options, val);
  EXPECT_EQ(from_dir.size(), 2);
  EXPECT_EQ(held_out.size(), 2);
  // The ramp at 30 fps: 2 cm a frame; training windows from its first 50 frames, validation ones
  // from its last 50.
  for (uint64_t seed = 0; seed < 8; ++seed) {
    const auto x_train = from_dir.Get({0}, seed).tensors.at("trans").select(-1, 0);
    const auto x_val = held_out.Get({0}, seed).tensors.at("trans").select(-1, 0);
    EXPECT_LT(x_train.max().item<double>(), 0.02 * 50 - 1e-4);
    EXPECT_GT(x_val.min().item<double>(), 0.02 * 50 - 1e-4);
    EXPECT_NEAR((x_train[0][1] - x_train[0][0]).item<double>(), 0.02, 1e-5);
  }
  // Datasets that share the model's files read each file once: the two parts of the clips, and
  // the triplets' train and val splits, from one read each, giving what separate reads give.
  auto files = std::make_shared<CleanupFiles>();
  plugin::DataContext both = train;
  both.config["triplets"] = WriteTriplets("cleanup_shared", 4, "train");
  CleanupDataset shared_train(options, both, files);
  EXPECT_EQ(files->reads(), 2);
  both.split = "val";
  CleanupDataset shared_val(options, both, files);
  EXPECT_EQ(files->reads(), 2);
  EXPECT_EQ(shared_train.size(), 2 + 4);
  EXPECT_EQ(shared_val.size(), 2 + 2);
  // The triplets' tracks come first, then the motions'.
  const auto val_batch = shared_val.Get({2, 3}, 5), alone = held_out.Get({0, 1}, 5);
  for (const char* name : {"trans", "given_trans", "legs", "noisy"}) {
    EXPECT_TRUE(torch::equal(val_batch.tensors.at(name), alone.tensors.at(name))) << name;
  }
  // A file that cannot be read is not kept as read: asked again, it is refused again.
  plugin::DataContext broken_file;
  broken_file.config = {{"triplets", ::testing::TempDir() + "/cleanup_shared_none"}};
  std::filesystem::create_directories(::testing::TempDir() + "/cleanup_shared_none");
  {
    std::ofstream broken(::testing::TempDir() + "/cleanup_shared_none/triplets-00000.npz");
    broken << "not an npz";
  }
  for (int attempt = 0; attempt < 2; ++attempt) {
    EXPECT_THROW(CleanupDataset(options, broken_file, files), std::invalid_argument);
  }
  EXPECT_EQ(files->reads(), 2);
  // Mended in place, the same file is read and used: no failure was kept for it.
  std::filesystem::copy_file(
      WriteTriplets("cleanup_shared_mended", 4, "train") + "/motionfix/triplets-00000.npz",
      ::testing::TempDir() + "/cleanup_shared_none/triplets-00000.npz",
      std::filesystem::copy_options::overwrite_existing);
  EXPECT_EQ(CleanupDataset(options, broken_file, files).size(), 2 * 2);  // both sides of 2 usable
  EXPECT_EQ(files->reads(), 3);
  // A list of files; together with triplets.
  plugin::DataContext listed;
  listed.config = {{"motions", nlohmann::json::array({dir + "/clips.npz"})}, {"val_fraction", 0.5}};
  EXPECT_EQ(CleanupDataset(options, listed).size(), 2);
  listed.config["triplets"] = WriteTriplets("cleanup_with_motions", 4, "train");
  EXPECT_EQ(CleanupDataset(options, listed).size(), 2 + 4);
  // A CMU BVH as shipped (120 fps, retargeted to SMPL-22): 8.28 s at 30 fps.
  plugin::DataContext bvh;
  bvh.config = {{"motions", MOTIONPIPE_DATA_DIR "/mocap/cmu/131_01.bvh"}};
  CleanupDataset cmu(options, bvh);
  ASSERT_EQ(cmu.size(), 1);
  const auto legs = cmu.Get({0}, 3).tensors.at("legs");
  EXPECT_EQ(legs.sizes(), (std::vector<int64_t>{1, 40, 6, 3, 3}));
  EXPECT_TRUE(torch::isfinite(legs).all().item<bool>());
  const auto expect_refused = [&](const nlohmann::json& config, const std::string& why,
                                  const CleanupOptions& o) {
    plugin::DataContext context;
    context.config = config;
    ExpectRefused(o, context, why);
  };
  expect_refused({{"motions", dir + "/nowhere"}}, "no such file or directory: " + dir + "/nowhere",
                 options);
  const std::string empty = ::testing::TempDir() + "/cleanup_no_motions";
  std::filesystem::create_directories(empty);
  expect_refused({{"motions", empty}}, "no motion files (.npz, .bvh) in " + empty, options);
  expect_refused({{"motions", 3}}, "data.motions: a file or directory, or a list of them", options);
  expect_refused({{"motions", dir}, {"val_fraction", 1.5}}, "val_fraction must be in (0, 1)",
                 options);
  // The default held-out tenth of 100 and 90 frames holds no 40-frame window.
  plugin::DataContext short_val;
  short_val.split = "val";
  short_val.config = {{"motions", dir}};
  ExpectRefused(options, short_val,
                "no motion has 40 frames or more in its held-out last 0.1 (data.val_fraction) at "
                "30 fps (1 file(s))");
  CleanupOptions long_crop = options;
  long_crop.crop = 120;
  expect_refused({{"motions", dir}}, "no motion has 120 frames or more in its training part",
                 long_crop);
}

TEST(LegCleanup, OptionsRefuseNonsense) {
  EXPECT_THROW(CleanupOptions::FromJson({{"width", 0}}), std::invalid_argument);
  EXPECT_THROW(CleanupOptions::FromJson({{"dilations", {1, 0}}}), std::invalid_argument);
  EXPECT_THROW(CleanupOptions::FromJson({{"crop", 4}}), std::invalid_argument);
  EXPECT_THROW(CleanupOptions::FromJson({{"corruption", {{"shrink", 1.5}}}}),
               std::invalid_argument);
  const auto round = CleanupOptions::FromJson(
      {{"height", true}, {"corruption", {{"shrink", 0.25}}}, {"loss", {{"slide", 0.5}}}});
  EXPECT_EQ(CleanupOptions::FromJson(round.ToJson()).ToJson(), round.ToJson());
  EXPECT_TRUE(round.height);
  EXPECT_EQ(round.shrink, 0.25);
  EXPECT_EQ(round.slide_weight, 0.5);
}

}  // namespace
}  // namespace motionpipe::legs
