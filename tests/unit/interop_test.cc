// Files cross the numpy boundary in both directions, with the real numpy (Debian's python3-numpy,
// which scripts/setup installs for /usr/bin/python3), and the MotionFix converter runs on a pickle
// written by joblib.
#include <gtest/gtest.h>

#include <cstdlib>

#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/formats/npz.h"
#include "test_util.h"

namespace motionpipe {
namespace {

int RunPython(const std::string& args) {
  const std::string command = "/usr/bin/python3 " + args;
  return std::system(command.c_str());
}

std::string Script() { return testing::SourceDir() + "/tests/python/numpy_interop.py"; }

TEST(NumpyInterop, NumpyLoadsOurClipFile) {
  Clip a;
  a.id = "upright";
  a.motion = Motion::Rest(12, 30, 0.9);
  a.texts = {"a person waves — with the right hand"};
  a.segments = {{0, 12, "wave", PartBit(BodyPart::kRightArm), ""}};
  Clip b;
  b.id = "second";
  b.motion = testing::SmoothMotion(20, 3);
  b.joints = ComputeJoints(Skeleton::Smpl22(), b.motion);
  a.joints = ComputeJoints(Skeleton::Smpl22(), a.motion);
  for (bool compress : {true, false}) {
    const std::string path =
        ::testing::TempDir() + (compress ? "/interop_deflated.npz" : "/interop_stored.npz");
    ASSERT_TRUE(WriteClips(path, {a, b}, compress).ok());
    EXPECT_EQ(RunPython(Script() + " check-clips " + path), 0);
  }
}

TEST(NumpyInterop, NumpyLoadsEveryDTypeWeWrite) {
  Npz npz;
  npz.Add("f32", NpyArray::Float32({2, 3}, {1, 2, 3, 4, 5, -6.5f}));
  npz.Add("f64", NpyArray::Float64({3}, {1.5, -2, 1e300}));
  npz.Add("i32", NpyArray::Int32({2}, {-7, 1 << 30}));
  npz.Add("i64", NpyArray::Int64({1}, {-(int64_t{1} << 50)}));
  npz.Add("b", NpyArray::Bool({4}, {1, 0, 0, 1}));
  npz.Add("u8", NpyArray::UInt8({2}, {0, 255}));
  npz.Add("s", NpyArray::Strings({3}, {"walk", "wave — right hand", ""}));
  npz.Add("scalar", NpyArray::ScalarFloat64(29.97));
  const std::string path = ::testing::TempDir() + "/interop_dtypes.npz";
  ASSERT_TRUE(WriteNpz(path, npz, true).ok());
  EXPECT_EQ(RunPython(Script() + " check-arrays " + path), 0);
}

TEST(NumpyInterop, WeReadWhatNumpyWrites) {
  const std::string dir = ::testing::TempDir() + "/numpy_written";
  ASSERT_EQ(RunPython(Script() + " write " + dir), 0);
  for (const char* name : {"stored.npz", "deflated.npz"}) {
    auto npz = ReadNpz(dir + "/" + name);
    ASSERT_TRUE(npz.ok()) << npz.status().ToString();
    auto f32 = (*npz->Get("f32", name))->ToFloat32(name);
    ASSERT_TRUE(f32.ok());
    EXPECT_EQ((*npz->Get("f32", name))->shape, (std::vector<int64_t>{2, 3, 4}));
    EXPECT_EQ((*f32)[23], 23.0f);
    EXPECT_EQ((*(*npz->Get("f64", name))->ToFloat64(name))[2], 1e300);
    EXPECT_EQ((*(*npz->Get("i64", name))->ToInt64(name))[0], -(int64_t{1} << 60));
    EXPECT_EQ((*(*npz->Get("i32", name))->ToInt64(name))[2], 2147483647);
    EXPECT_EQ((*(*npz->Get("u8", name))->ToInt64(name))[2], 255);
    EXPECT_EQ((*(*npz->Get("b", name))->ToInt64(name)), (std::vector<int64_t>{1, 0, 1}));
    EXPECT_EQ((*(*npz->Get("u", name))->ToStrings(name))[1], "wave — right hand");
    EXPECT_EQ((*(*npz->Get("scalar", name))->ToFloat64(name))[0], 29.97);
    EXPECT_EQ((*(*npz->Get("fortran", name))->ToInt64(name)),
              (std::vector<int64_t>{0, 1, 2, 3, 4, 5}));
    EXPECT_EQ((*(*npz->Get("bigendian", name))->ToFloat64(name)),
              (std::vector<double>{0, 1, 2, 3}));
    EXPECT_EQ((*npz->Get("empty", name))->shape, (std::vector<int64_t>{0, 3}));
  }
  auto npy = ReadNpy(dir + "/plain.npy");
  ASSERT_TRUE(npy.ok());
  EXPECT_EQ(npy->shape, (std::vector<int64_t>{2, 3, 4}));
}

TEST(MotionFixConverter, ConvertsAJoblibPickleToOurLayout) {
  const std::string dir = ::testing::TempDir() + "/motionfix";
  ASSERT_EQ(RunPython(Script() + " motionfix-pickle " + dir), 0);
  const std::string out = dir + "/motionfix.npz";
  ASSERT_EQ(RunPython(testing::SourceDir() + "/tools/motionfix_convert.py " + dir +
                      "/motionfix.pth.tar --splits " + dir + "/splits.json --out " + out),
            0);
  auto triplets = ReadTriplets(out);
  ASSERT_TRUE(triplets.ok()) << triplets.status().ToString();
  ASSERT_EQ(triplets->size(), 3u);
  const Triplet& t = (*triplets)[1];
  EXPECT_EQ(t.id, "001");
  EXPECT_EQ(t.text, "walk faster");
  EXPECT_EQ(t.split, "test");
  EXPECT_EQ(t.source.num_frames(), 25);
  EXPECT_EQ(t.target.num_frames(), 30);
  EXPECT_EQ(t.source.fps, 30);
  EXPECT_EQ(t.source_joints.size(), 25u * 66u);
  auto expected = ReadNpy(dir + "/expected_rots_001.npy");
  ASSERT_TRUE(expected.ok());
  EXPECT_EQ(*expected->ToFloat32("rots"), t.source.poses);
  EXPECT_EQ((*triplets)[2].split, "train");
  // A damaged pickle is refused with the file name.
  std::FILE* f = std::fopen((dir + "/broken.pth.tar").c_str(), "w");
  std::fputs("not a pickle", f);
  std::fclose(f);
  EXPECT_NE(RunPython(testing::SourceDir() + "/tools/motionfix_convert.py " + dir +
                      "/broken.pth.tar --out " + dir + "/x.npz 2> " + dir + "/err.txt"),
            0);
}

}  // namespace
}  // namespace motionpipe
