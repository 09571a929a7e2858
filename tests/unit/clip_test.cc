#include "motionpipe/formats/clip.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "motionpipe/base/job_layout.h"
#include "motionpipe/formats/amass.h"
#include "motionpipe/formats/humanml3d.h"
#include "motionpipe/formats/motionfix.h"
#include "test_util.h"

namespace motionpipe {
namespace {

Clip MakeClip(const std::string& id, int64_t frames, uint32_t seed) {
  Clip clip;
  clip.id = id;
  clip.source = "test";
  clip.motion = testing::SmoothMotion(frames, seed);
  clip.texts = {"a person walks in a circle", "walk in a circle"};
  clip.segments = {{0, static_cast<int32_t>(frames / 2), "walk",
                    PartBit(BodyPart::kGlobal) | PartBit(BodyPart::kLeftLeg), ""},
                   {static_cast<int32_t>(frames / 4), static_cast<int32_t>(frames),
                    "wave right hand", PartBit(BodyPart::kRightArm), ""}};
  return clip;
}

TEST(Clips, WriteReadRoundTrip) {
  std::vector<Clip> clips = {MakeClip("a", 40, 1), MakeClip("b", 25, 2)};
  clips[1].texts.clear();
  const std::string path = ::testing::TempDir() + "/clips.npz";
  ASSERT_TRUE(WriteClips(path, clips).ok());
  auto back = ReadClips(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->size(), 2u);
  EXPECT_EQ((*back)[0].motion.poses, clips[0].motion.poses);
  EXPECT_EQ((*back)[1].motion.trans, clips[1].motion.trans);
  EXPECT_EQ((*back)[0].texts, clips[0].texts);
  EXPECT_TRUE((*back)[1].texts.empty());
  ASSERT_EQ((*back)[0].segments.size(), 2u);
  EXPECT_EQ((*back)[0].segments[1].text, "wave right hand");
  EXPECT_EQ((*back)[0].segments[1].parts, PartBit(BodyPart::kRightArm));
  EXPECT_EQ((*back)[1].segments[0].end_frame, 12);
}

TEST(Clips, InvalidClipsAreRefusedWithTheirName) {
  Clip clip = MakeClip("bad", 20, 1);
  clip.segments[0].end_frame = 99;
  const Status s = WriteClips(::testing::TempDir() + "/bad.npz", {clip});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("clip 'bad': segment 'walk' [0, 99)"), std::string::npos)
      << s.message();
  Clip nan = MakeClip("nan", 20, 1);
  nan.motion.poses[5] = std::numeric_limits<float>::infinity();
  EXPECT_FALSE(WriteClips(::testing::TempDir() + "/nan.npz", {nan}).ok());
}

TEST(Clips, DamagedOffsetsAreDataLoss) {
  Npz npz = ClipsToNpz({MakeClip("a", 10, 1)});
  npz.Add("offsets", NpyArray::Int64({2}, {0, 11}));
  auto bad = ClipsFromNpz(npz, "x.npz");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kDataLoss);
  npz = ClipsToNpz({MakeClip("a", 10, 1)});
  npz.Add("format", NpyArray::ScalarString("something else"));
  EXPECT_FALSE(ClipsFromNpz(npz, "x.npz").ok());
}

TEST(Amass, ReadsSmplhAndSmplxLayoutsAndResamples) {
  const Motion motion = testing::SmoothMotion(120, 4, 120);
  Npz smplh = AmassNpzFromMotion(motion);
  auto clip = AmassClipFromNpz(smplh, "walk_poses.npz");
  ASSERT_TRUE(clip.ok()) << clip.status().ToString();
  EXPECT_EQ(clip->motion.poses, motion.poses);
  EXPECT_EQ(clip->motion.fps, 120);
  // SMPL-X: 165 columns, float64, and mocap_frame_rate.
  Npz smplx;
  std::vector<double> poses(120 * 165, 0.0);
  for (int64_t f = 0; f < 120; ++f) {
    for (int c = 0; c < 66; ++c)
      poses[static_cast<size_t>(f * 165 + c)] = motion.poses[static_cast<size_t>(f * 66 + c)];
  }
  smplx.Add("poses", NpyArray::Float64({120, 165}, poses));
  smplx.Add("trans", NpyArray::Float32({120, 3}, motion.trans));
  smplx.Add("mocap_frame_rate", NpyArray::ScalarFloat64(120));
  const std::string path = ::testing::TempDir() + "/smplx.npz";
  ASSERT_TRUE(WriteNpz(path, smplx).ok());
  auto resampled = ReadAmassNpz(path, 30);
  ASSERT_TRUE(resampled.ok()) << resampled.status().ToString();
  EXPECT_EQ(resampled->motion.num_frames(), 30);
  EXPECT_FLOAT_EQ(resampled->motion.poses[66], motion.poses[4 * 66]);
  Npz broken = smplh;
  broken.Add("poses", NpyArray::Float32({120, 10}, std::vector<float>(1200, 0)));
  auto bad = AmassClipFromNpz(broken, "b.npz");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("b.npz: 'poses' has shape (120, 10)"), std::string::npos);
}

TEST(LoadMotionFile, DispatchesOnContentAndKeepsSegmentsWhenResampling) {
  const std::string amass = ::testing::TempDir() + "/any_amass.npz";
  ASSERT_TRUE(WriteNpz(amass, AmassNpzFromMotion(testing::SmoothMotion(60, 2, 60))).ok());
  auto a = LoadMotionFile(amass, 30);
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->front().motion.num_frames(), 30);
  const std::string clips = ::testing::TempDir() + "/any_clips.npz";
  Clip clip = MakeClip("c", 60, 3);
  clip.motion.fps = 60;
  ASSERT_TRUE(WriteClips(clips, {clip}).ok());
  auto c = LoadMotionFile(clips, 30);
  ASSERT_TRUE(c.ok());
  ASSERT_EQ(c->front().segments.size(), 2u);
  EXPECT_EQ(c->front().segments[0].end_frame, 15);  // frames [0, 30) at 60 fps -> [0, 15) at 30
  const std::string junk = ::testing::TempDir() + "/junk.npz";
  Npz npz;
  npz.Add("x", NpyArray::Float32({1}, {1}));
  ASSERT_TRUE(WriteNpz(junk, npz).ok());
  EXPECT_FALSE(LoadMotionFile(junk).ok());
}

TEST(Triplets, RoundTripWithJointsAndEditRange) {
  std::vector<Triplet> triplets(2);
  for (size_t k = 0; k < 2; ++k) {
    triplets[k].id = "t" + std::to_string(k);
    triplets[k].text = k ? "raise the right arm higher" : "walk faster";
    triplets[k].split = k ? "test" : "train";
    triplets[k].source =
        testing::SmoothMotion(30 + static_cast<int64_t>(k) * 5, static_cast<uint32_t>(k));
    triplets[k].target = testing::SmoothMotion(28, static_cast<uint32_t>(k) + 10);
    triplets[k].source_joints = ComputeJoints(Skeleton::Smpl22(), triplets[k].source);
    triplets[k].target_joints = ComputeJoints(Skeleton::Smpl22(), triplets[k].target);
  }
  triplets[1].edit_start = 5;
  triplets[1].edit_end = 20;
  const std::string path = ::testing::TempDir() + "/triplets.npz";
  ASSERT_TRUE(WriteTriplets(path, triplets).ok());
  auto back = ReadTriplets(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->size(), 2u);
  EXPECT_EQ((*back)[1].text, "raise the right arm higher");
  EXPECT_EQ((*back)[1].source.poses, triplets[1].source.poses);
  EXPECT_EQ((*back)[1].target_joints, triplets[1].target_joints);
  EXPECT_EQ((*back)[1].edit_end, 20);
  EXPECT_EQ((*back)[0].edit_start, -1);
}

// One rule finds a directory's triplet files: motionfix/triplets*.npz (a corpus or dataset stage's
// output) before triplets*.npz beside it, sorted; other files are not triplets.
TEST(Triplets, TripletFilesInPrefersTheMotionfixFolderAndSorts) {
  namespace fs = std::filesystem;
  const std::string dir = ::testing::TempDir() + "/triplet_files";
  fs::remove_all(dir);
  fs::create_directories(dir + "/motionfix");
  const auto touch = [](const std::string& path) { std::ofstream(path) << "x"; };
  EXPECT_TRUE(TripletFilesIn(dir).empty());
  EXPECT_TRUE(TripletFilesIn(dir + "/missing").empty());
  touch(dir + "/triplets-00001.npz");
  touch(dir + "/triplets-00000.npz");
  touch(dir + "/clips-00000.npz");
  touch(dir + "/triplets-notes.txt");
  EXPECT_EQ(TripletFilesIn(dir),
            (std::vector<std::string>{dir + "/triplets-00000.npz", dir + "/triplets-00001.npz"}));
  touch(dir + "/motionfix/triplets-train.npz");
  EXPECT_EQ(TripletFilesIn(dir), (std::vector<std::string>{dir + "/motionfix/triplets-train.npz"}));
  fs::remove_all(dir);
}

// A stage's triplets are read once: from its result when that holds any (a corpus: the result's
// files are its tasks' shards again), else from each task; stages are judged one by one, by the
// directory they share; a result with no triplets (a filter's) leaves its tasks'.
TEST(Triplets, StageTripletFilesReadAStageOnceResultFirst) {
  namespace fs = std::filesystem;
  const std::string job = ::testing::TempDir() + "/stage_triplet_files";
  fs::remove_all(job);
  const auto touch = [](const std::string& path) {
    fs::create_directories(fs::path(path).parent_path());
    std::ofstream(path) << "x";
  };
  for (const char* shard : {"00000", "00001"}) {
    touch(job + "/corpus/task-" + shard + "/motionfix/triplets-" + shard + ".npz");
    touch(job + "/corpus/result/motionfix/triplets-" + shard + ".npz");
    touch(job + "/dataset/task-" + shard + "/triplets-" + shard + ".npz");
  }
  fs::create_directories(job + "/dataset/result");  // a result without triplets
  const std::vector<std::string> corpus = layout::StageOutputDirs(job + "/corpus"),
                                 dataset = layout::StageOutputDirs(job + "/dataset");
  ASSERT_EQ(corpus.size(), 3u);
  const std::vector<std::string> from_corpus = {
      job + "/corpus/result/motionfix/triplets-00000.npz",
      job + "/corpus/result/motionfix/triplets-00001.npz"};
  EXPECT_EQ(StageTripletFiles(corpus), from_corpus);
  std::vector<std::string> dirs = {job + "/corpus/task-00001", job + "/corpus/result"};
  EXPECT_EQ(StageTripletFiles(dirs), from_corpus);  // in any order
  dirs = {job + "/corpus/task-00001/", job + "/corpus/result/"};
  EXPECT_EQ(StageTripletFiles(dirs).size(), 2u);  // a result named with a trailing slash
  const std::vector<std::string> from_dataset = {job + "/dataset/task-00000/triplets-00000.npz",
                                                 job + "/dataset/task-00001/triplets-00001.npz"};
  EXPECT_EQ(StageTripletFiles(dataset), from_dataset);
  dirs = dataset;
  dirs.insert(dirs.end(), corpus.begin(), corpus.end());
  std::vector<std::string> both = from_corpus;
  both.insert(both.end(), from_dataset.begin(), from_dataset.end());
  EXPECT_EQ(StageTripletFiles(dirs), both);
  // A task directory alone (no result among the directories) is read.
  EXPECT_EQ(StageTripletFiles({job + "/corpus/task-00001"}),
            std::vector<std::string>{job + "/corpus/task-00001/motionfix/triplets-00001.npz"});
  EXPECT_TRUE(StageTripletFiles({job + "/missing"}).empty());
  fs::remove_all(job);
}

// Both sides of a split's triplets, in row order, named by file, triplet and side; `limit`
// counts triplets; a visitor's error ends the visit and is returned; a bad file is named.
TEST(Triplets, VisitTripletSidesReadsASplitsBothSidesInRowOrder) {
  std::vector<Triplet> triplets(4);
  for (size_t k = 0; k < triplets.size(); ++k) {
    triplets[k].id = "t" + std::to_string(k);
    triplets[k].text = "walk";
    triplets[k].split = k == 1 ? "test" : "train";
    triplets[k].source = testing::SmoothMotion(20 + static_cast<int64_t>(k), 1);
    triplets[k].target = testing::SmoothMotion(30 + static_cast<int64_t>(k), 2);
  }
  const std::string path = ::testing::TempDir() + "/visit_triplets.npz";
  ASSERT_TRUE(WriteTriplets(path, triplets).ok());
  std::vector<std::string> origins;
  std::vector<int64_t> frames;
  const auto record = [&](const Motion& motion, const std::string& origin) {
    origins.push_back(origin);
    frames.push_back(motion.num_frames());
    return Status::Ok();
  };
  auto visited = VisitTripletSides(path, "train", 0, record);
  ASSERT_TRUE(visited.ok()) << visited.status().ToString();
  EXPECT_EQ(*visited, 3);
  EXPECT_EQ(frames, (std::vector<int64_t>{20, 30, 22, 32, 23, 33}));
  EXPECT_EQ(origins[0], path + ", triplet 't0' (source)");
  EXPECT_EQ(origins[3], path + ", triplet 't2' (target)");
  origins.clear();
  frames.clear();
  visited = VisitTripletSides(path, "train", 2, record);
  ASSERT_TRUE(visited.ok());
  EXPECT_EQ(*visited, 2);
  EXPECT_EQ(frames, (std::vector<int64_t>{20, 30, 22, 32}));
  EXPECT_EQ(*VisitTripletSides(path, "val", 0, record), 0);
  int calls = 0;
  visited = VisitTripletSides(path, "train", 0, [&](const Motion&, const std::string& origin) {
    ++calls;
    return InvalidArgument(origin + ": refused");
  });
  ASSERT_FALSE(visited.ok());
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(visited.status().message(), path + ", triplet 't0' (source): refused");
  const auto missing = VisitTripletSides(path + ".missing", "train", 0, record);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find(path + ".missing"), std::string::npos);
}

TEST(HumanML3D, JointsConvertFromYUpToZUp) {
  std::vector<float> joints(2 * 22 * 3, 0.0f);
  joints[15 * 3 + 1] = 1.6f;  // head 1.6 m up (y)
  joints[10 * 3 + 2] = 0.2f;  // left foot forward (+z in y-up)
  const std::string path = ::testing::TempDir() + "/000001.npy";
  ASSERT_TRUE(WriteNpy(path, NpyArray::Float32({2, 22, 3}, joints)).ok());
  auto seq = ReadHumanML3DJoints(path);
  ASSERT_TRUE(seq.ok());
  EXPECT_EQ(seq->frames, 2);
  EXPECT_FLOAT_EQ(seq->joints[15 * 3 + 2], 1.6f);
  EXPECT_FLOAT_EQ(seq->joints[10 * 3 + 1], -0.2f);  // forward is -y in our z-up world
  ASSERT_TRUE(WriteNpy(path, NpyArray::Float32({2, 21, 3}, std::vector<float>(126, 0))).ok());
  EXPECT_FALSE(ReadHumanML3DJoints(path).ok());
}

}  // namespace
}  // namespace motionpipe
