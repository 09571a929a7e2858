// What a model's own frame rate does to the plausibility figures (issue 15): motions taken to the
// rate by index (as the MDT's and SINC's training data are cut), each frame's local rotations
// then turned by independent noise (a network's frame-to-frame error, of a given spread), and
// brought back by the two upsamplings a generator offers (`upsample: linear`, slerp and lerp, and
// `cubic`, a Catmull-Rom spline; motion.h). Prints the jerk, the foot skate and GMD's skating
// ratio of each beside the original motions': how much of an edit's figures the round trip
// itself makes, and how precise a network's frames must be for the feet to stay planted.
//
//   upsample_bench [--clips N] [--seed S] [--fps F] [--noise DEG,DEG,...] [--joints legs|all]
//                  [MOTION_FILE ...]
//
// The corpus is the procedural one (`clips` of the default corpus's scripts, generated into a
// temporary folder and removed); motion files (BVH, AMASS npz, our clip layout, at 30 fps) make
// a second table. Noise is a rotation vector per frame and joint with each component normal of
// spread DEG degrees, deterministic for --seed.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "motionpipe/corpus/corpus.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/math/rotation.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/motion/plausibility.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {
namespace {

struct Args {
  int64_t clips = 400;
  uint64_t seed = 1;
  double fps = 10;
  std::vector<double> noise = {0, 0.1, 0.2, 0.3, 0.5, 1};
  bool legs_only = false;
  std::vector<std::string> files;
};

[[noreturn]] void Usage(const char* why) {
  std::fprintf(stderr,
               "upsample_bench: %s\nusage: upsample_bench [--clips N] [--seed S] [--fps F] "
               "[--noise DEG,DEG,...] [--joints legs|all] [MOTION_FILE ...]\n",
               why);
  std::exit(2);
}

Args ParseArgs(int argc, char** argv) {
  Args a;
  for (int k = 1; k < argc; ++k) {
    const bool has_value = k + 1 < argc;
    if (!std::strcmp(argv[k], "--clips") && has_value) {
      a.clips = std::atoll(argv[++k]);
    } else if (!std::strcmp(argv[k], "--seed") && has_value) {
      a.seed = std::strtoull(argv[++k], nullptr, 10);
    } else if (!std::strcmp(argv[k], "--fps") && has_value) {
      a.fps = std::atof(argv[++k]);
    } else if (!std::strcmp(argv[k], "--noise") && has_value) {
      a.noise.clear();
      std::string list = argv[++k];
      for (size_t at = 0; at <= list.size();) {
        const size_t comma = std::min(list.find(',', at), list.size());
        a.noise.push_back(std::atof(list.substr(at, comma - at).c_str()));
        at = comma + 1;
      }
    } else if (!std::strcmp(argv[k], "--joints") && has_value) {
      const std::string joints = argv[++k];
      if (joints != "legs" && joints != "all") Usage("--joints is legs or all");
      a.legs_only = joints == "legs";
    } else if (argv[k][0] == '-') {
      Usage((std::string("unknown option ") + argv[k]).c_str());
    } else {
      a.files.push_back(argv[k]);
    }
  }
  if (a.clips < 1 || !(a.fps > 0) || a.noise.empty()) Usage("bad --clips, --fps or --noise");
  return a;
}

struct Figures {
  double jerk = 0, skate = 0, gmd = 0;
  int64_t motions = 0;
  void Add(const PlausibilityReport& r) {
    jerk += r.jerk_mean;
    skate += r.foot_skate_ratio;
    gmd += r.skating_ratio_gmd;
    ++motions;
  }
  void Print(const std::string& row) const {
    const double n = static_cast<double>(std::max<int64_t>(1, motions));
    std::printf("%-44s %10.1f %8.3f %8.3f\n", row.c_str(), jerk / n, skate / n, gmd / n);
  }
};

// `motion` with each frame's local rotations of `joints` turned by a random rotation vector whose
// components are normal with spread `degrees`.
Motion WithNoise(Motion motion, const std::vector<int>& joints, double degrees, std::mt19937& rng) {
  if (degrees <= 0) return motion;
  std::normal_distribution<double> normal(0, degrees * kPi / 180);
  for (int64_t frame = 0; frame < motion.num_frames(); ++frame) {
    for (int joint : joints) {
      const Vec3 turn{normal(rng), normal(rng), normal(rng)};
      motion.SetLocalRotation(frame, joint,
                              motion.LocalRotation(frame, joint) * AxisAngleToMatrix(turn));
    }
  }
  return motion;
}

void Table(const std::string& title, const std::vector<Motion>& motions, const Args& a) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  std::vector<int> joints;
  for (int joint = 1; joint < kNumJoints; ++joint) {
    const BodyPart part = skeleton.part_of_joint(joint);
    if (!a.legs_only || part == BodyPart::kLeftLeg || part == BodyPart::kRightLeg)
      joints.push_back(joint);
  }
  std::printf("\n%s: %zu motions; noise on %s, per frame at %g fps\n", title.c_str(),
              motions.size(), a.legs_only ? "the legs' joints" : "every joint but the pelvis",
              a.fps);
  std::printf("%-44s %10s %8s %8s\n", "motions", "jerk m/s3", "skate", "GMD's");
  Figures original;
  for (const Motion& m : motions) original.Add(EvaluateMotionPlausibility(skeleton, m));
  original.Print("original");
  for (double degrees : a.noise) {
    Figures linear, cubic;
    std::mt19937 rng(static_cast<uint32_t>(a.seed));
    for (const Motion& m : motions) {
      const Motion low = WithNoise(ToModelRate(m, a.fps), joints, degrees, rng);
      for (auto [method, figures] : {std::pair{ResampleMethod::kInterpolate, &linear},
                                     std::pair{ResampleMethod::kCubic, &cubic}}) {
        const Result<Motion> back = ResampleToFrames(low, m.fps, m.num_frames(), method);
        if (!back.ok()) Usage(back.status().message().c_str());
        figures->Add(EvaluateMotionPlausibility(skeleton, *back));
      }
    }
    char row[96];
    std::snprintf(row, sizeof(row), "through %g fps, noise %g deg: linear", a.fps, degrees);
    linear.Print(row);
    std::snprintf(row, sizeof(row), "through %g fps, noise %g deg: cubic", a.fps, degrees);
    cubic.Print(row);
  }
}

}  // namespace
}  // namespace motionpipe

int main(int argc, char** argv) {
  using namespace motionpipe;
  const Args a = ParseArgs(argc, argv);
  char folder[] = "/tmp/upsample_bench.XXXXXX";
  if (!mkdtemp(folder)) Usage("cannot make a temporary folder");
  corpus::CorpusOptions options;
  options.out_dir = folder;
  options.seed = a.seed;
  options.clips = a.clips;
  options.triplets = 1;
  options.write_amass = false;
  const Result<corpus::CorpusSummary> made = corpus::GenerateCorpus(options);
  std::vector<Motion> procedural;
  if (made.ok()) {
    for (const auto& entry : std::filesystem::directory_iterator(std::string(folder) + "/clips")) {
      const Result<std::vector<Clip>> clips = ReadClips(entry.path().string());
      if (!clips.ok()) Usage(clips.status().message().c_str());
      for (const Clip& clip : *clips) procedural.push_back(clip.motion);
    }
  }
  std::filesystem::remove_all(folder);
  if (!made.ok()) Usage(made.status().message().c_str());
  Table("the procedural corpus (seed " + std::to_string(a.seed) + ")", procedural, a);
  if (!a.files.empty()) {
    std::vector<Motion> files;
    for (const std::string& path : a.files) {
      const Result<std::vector<Clip>> clips = LoadMotionFile(path, 30);
      if (!clips.ok()) Usage(clips.status().message().c_str());
      for (const Clip& clip : *clips) files.push_back(clip.motion);
    }
    Table("motion files", files, a);
  }
  return 0;
}
