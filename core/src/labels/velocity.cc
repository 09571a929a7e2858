#include "velocity.h"

#include <cmath>

namespace motionpipe::labels {

std::array<double, kNumBodyParts> PartSpeeds(const Motion& motion) {
  std::array<double, kNumBodyParts> speeds{};
  const int64_t frames = motion.num_frames();
  if (frames < 2 || motion.fps <= 0) return speeds;
  const Skeleton& skeleton = Skeleton::Smpl22();
  const std::vector<float> joints = ComputeJoints(skeleton, motion);
  auto at = [&](int64_t f, int j, int a) {
    return static_cast<double>(joints[static_cast<size_t>((f * kNumJoints + j) * 3 + a)]);
  };
  const auto& part_joints = skeleton.part_joints();
  for (int part = 0; part < kNumBodyParts; ++part) {
    double total = 0;
    int64_t count = 0;
    for (const int j : part_joints[static_cast<size_t>(part)]) {
      for (int64_t f = 1; f < frames; ++f) {
        double d2 = 0;
        for (int a = 0; a < 3; ++a) {
          double now = at(f, j, a), before = at(f - 1, j, a);
          if (part != static_cast<int>(BodyPart::kGlobal)) {  // relative to the pelvis
            now -= at(f, 0, a);
            before -= at(f - 1, 0, a);
          }
          d2 += (now - before) * (now - before);
        }
        total += std::sqrt(d2) * motion.fps;
        ++count;
      }
    }
    speeds[static_cast<size_t>(part)] = count > 0 ? total / static_cast<double>(count) : 0;
  }
  return speeds;
}

namespace {

class VelocityLabeler : public Labeler {
 public:
  VelocityLabeler(double threshold, int min_batch, double absolute)
      : threshold_(threshold), min_batch_(min_batch), absolute_(absolute) {}
  std::string Name() const override { return "velocity"; }
  bool NeedsMotion() const override { return true; }
  Result<std::vector<PartSet>> Label(const std::vector<LabelInput>& inputs) override {
    std::vector<std::array<double, kNumBodyParts>> speeds;
    for (const auto& input : inputs) {
      if (!input.motion)
        return InvalidArgument("velocity labeler: '" + input.text +
                               "' has no motion (it labels motions, not texts)");
      speeds.push_back(PartSpeeds(*input.motion));
    }
    std::array<double, kNumBodyParts> mean{}, stddev{};
    const bool standardise = static_cast<int>(inputs.size()) >= min_batch_;
    if (standardise) {
      for (const auto& s : speeds) {
        for (int p = 0; p < kNumBodyParts; ++p)
          mean[static_cast<size_t>(p)] += s[static_cast<size_t>(p)];
      }
      for (double& m : mean) m /= static_cast<double>(speeds.size());
      for (const auto& s : speeds) {
        for (int p = 0; p < kNumBodyParts; ++p) {
          const double d = s[static_cast<size_t>(p)] - mean[static_cast<size_t>(p)];
          stddev[static_cast<size_t>(p)] += d * d;
        }
      }
      for (double& sd : stddev)
        sd = std::sqrt(sd / static_cast<double>(std::max<size_t>(1, speeds.size() - 1)));
    }
    std::vector<PartSet> out;
    for (const auto& s : speeds) {
      PartSet parts = 0;
      for (int p = 0; p < kNumBodyParts; ++p) {
        const auto i = static_cast<size_t>(p);
        const bool moving = standardise
                                ? (stddev[i] > 0 && (s[i] - mean[i]) / stddev[i] > threshold_)
                                : s[i] > absolute_;
        if (moving) parts |= static_cast<PartSet>(1u << p);
      }
      out.push_back(parts);
    }
    return out;
  }

 private:
  double threshold_;
  int min_batch_;
  double absolute_;
};

}  // namespace

Result<std::unique_ptr<Labeler>> MakeVelocityLabeler(const nlohmann::json& config) {
  return std::unique_ptr<Labeler>(new VelocityLabeler(config.value("threshold", 0.25),
                                                      config.value("min_batch", 20),
                                                      config.value("absolute", 0.15)));
}

}  // namespace motionpipe::labels
