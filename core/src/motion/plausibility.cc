#include "motionpipe/motion/plausibility.h"

#include <algorithm>
#include <cmath>

namespace motionpipe {

namespace {

constexpr double kRadToDeg = 180.0 / kPi;

// Largest total rotation (degrees) per joint, loosely human: knees and elbows fold to ~165 deg,
// the spine joints each bend a fraction of the back's range.
double MaxRotationDegrees(int joint) {
  switch (joint) {
    case 0:
      return 360;  // global orientation: free
    case 1:
    case 2:
      return 140;  // hips
    case 4:
    case 5:
      return 165;  // knees
    case 7:
    case 8:
      return 75;  // ankles
    case 10:
    case 11:
      return 60;  // toes
    case 3:
    case 6:
    case 9:
      return 60;  // spine
    case 12:
    case 15:
      return 75;  // neck, head
    case 13:
    case 14:
      return 50;  // collars
    case 16:
    case 17:
      return 180;  // shoulders: free
    case 18:
    case 19:
      return 165;  // elbows
    case 20:
    case 21:
      return 130;  // wrists (SMPL puts part of the forearm twist here)
    default:
      return 180;
  }
}

// GMD's skating ratio (Karunratanakul et al. 2023, "Guided Motion Diffusion"; OmniControl reports
// the same): toe joints at 20 fps, heights above the floor, contact below 5 cm in both frames of a
// pair, skating when the pair's horizontal speed and its mean over a centred window of 5 pairs
// (zeros beyond the ends) both exceed 0.5 m/s; the ratio counts pairs in which either foot skates.
double GmdSkatingRatio(const Skeleton& skeleton, const float* joints, int64_t frames, double fps,
                       double floor) {
  constexpr double kRate = 20, kHeight = 0.05, kSpeed = 0.5;
  constexpr int64_t kWindow = 5;
  if (frames < 2 || fps <= 0) return 0;
  const int64_t samples = static_cast<int64_t>(std::floor((frames - 1) * kRate / fps + 1e-9)) + 1;
  const int64_t pairs = samples - 1;
  if (pairs < 1) return 0;
  const int toes[2] = {skeleton.left_foot_joints()[1], skeleton.right_foot_joints()[1]};
  // Linear resampling of one toe to 20 fps.
  const auto toe_at = [&](int64_t sample, int joint) {
    const double x = static_cast<double>(sample) * fps / kRate;
    const int64_t i0 = std::min<int64_t>(static_cast<int64_t>(x), frames - 1);
    const int64_t i1 = std::min<int64_t>(i0 + 1, frames - 1);
    const double w = x - static_cast<double>(i0);
    const float* a = joints + (i0 * kNumJoints + joint) * 3;
    const float* b = joints + (i1 * kNumJoints + joint) * 3;
    return Vec3{(1 - w) * a[0] + w * b[0], (1 - w) * a[1] + w * b[1], (1 - w) * a[2] + w * b[2]};
  };
  std::vector<char> skating(static_cast<size_t>(pairs), 0);
  std::vector<double> speed(static_cast<size_t>(pairs));
  std::vector<char> contact(static_cast<size_t>(pairs));
  for (int joint : toes) {
    Vec3 previous = toe_at(0, joint);
    for (int64_t i = 0; i < pairs; ++i) {
      const Vec3 next = toe_at(i + 1, joint);
      speed[static_cast<size_t>(i)] = std::hypot(next.x - previous.x, next.y - previous.y) * kRate;
      contact[static_cast<size_t>(i)] = previous.z - floor < kHeight && next.z - floor < kHeight;
      previous = next;
    }
    for (int64_t i = 0; i < pairs; ++i) {
      double window = 0;
      for (int64_t j = i - kWindow / 2; j <= i + kWindow / 2; ++j)
        if (j >= 0 && j < pairs) window += speed[static_cast<size_t>(j)];
      const size_t k = static_cast<size_t>(i);
      if (contact[k] && speed[k] > kSpeed && window / kWindow > kSpeed) skating[k] = 1;
    }
  }
  int64_t count = 0;
  for (char s : skating) count += s;
  return static_cast<double>(count) / static_cast<double>(pairs);
}

}  // namespace

std::string CheckJointLimit(const Skeleton& skeleton, int joint, const Mat3& local) {
  const Vec3 aa = MatrixToAxisAngle(local);
  const double angle = Norm(aa) * kRadToDeg;
  const double limit = MaxRotationDegrees(joint);
  const std::string& name = skeleton.joint_names()[static_cast<size_t>(joint)];
  char buffer[128];
  if (angle > limit) {
    std::snprintf(buffer, sizeof(buffer), "%s rotated %.0f deg (limit %.0f)", name.c_str(), angle,
                  limit);
    return buffer;
  }
  // Hinges must not bend backwards: knees flex about +x, the left elbow about -y, the right about
  // +y.
  double flexion = 0;
  if (joint == 4 || joint == 5) flexion = std::atan2(local.m[2][1], local.m[1][1]);
  if (joint == 18) flexion = -std::atan2(local.m[0][2], local.m[0][0]);
  if (joint == 19) flexion = std::atan2(local.m[0][2], local.m[0][0]);
  if ((joint == 4 || joint == 5 || joint == 18 || joint == 19) && flexion * kRadToDeg < -15) {
    std::snprintf(buffer, sizeof(buffer), "%s hyperextended by %.0f deg", name.c_str(),
                  -flexion * kRadToDeg);
    return buffer;
  }
  return "";
}

PlausibilityReport EvaluatePlausibility(const Skeleton& skeleton, const float* joints,
                                        int64_t frames, double fps, const std::vector<Mat3>* local,
                                        const PlausibilityOptions& options) {
  PlausibilityReport report;
  report.frames = frames;
  if (frames <= 0) return report;
  const auto at = [&](int64_t frame, int joint) {
    const float* p = joints + (frame * kNumJoints + joint) * 3;
    return Vec3{p[0], p[1], p[2]};
  };
  const int feet[4] = {skeleton.left_foot_joints()[0], skeleton.left_foot_joints()[1],
                       skeleton.right_foot_joints()[0], skeleton.right_foot_joints()[1]};
  double skate_sum = 0;
  int64_t contact = 0, skating = 0, floating = 0;
  double penetration_sum = 0;
  for (int64_t frame = 0; frame < frames; ++frame) {
    double lowest = 1e30;
    for (int joint = 0; joint < kNumJoints; ++joint) lowest = std::min(lowest, at(frame, joint).z);
    const double depth = std::max(0.0, options.floor - lowest);
    report.penetration_max = std::max(report.penetration_max, depth);
    penetration_sum += depth;
    if (lowest > options.floor + options.float_height) ++floating;
    for (int joint = 0; joint < kNumJoints; ++joint) {
      const int parent = skeleton.parents()[static_cast<size_t>(joint)];
      if (parent >= 0) {
        const double length = Norm(at(frame, joint) - at(frame, parent));
        report.bone_length_error =
            std::max(report.bone_length_error,
                     std::abs(length - skeleton.bone_lengths()[static_cast<size_t>(joint)]));
      }
      if (frame > 0)
        report.max_joint_step =
            std::max(report.max_joint_step, Norm(at(frame, joint) - at(frame - 1, joint)));
    }
    if (frame == 0) continue;
    for (int joint : feet) {
      const Vec3 a = at(frame - 1, joint), b = at(frame, joint);
      if (a.z > options.floor + options.contact_height ||
          b.z > options.floor + options.contact_height)
        continue;
      const double speed = std::hypot(b.x - a.x, b.y - a.y) * fps;
      skate_sum += speed;
      ++contact;
      skating += speed > options.skate_speed;
    }
  }
  report.penetration_mean = penetration_sum / static_cast<double>(frames);
  report.float_ratio = static_cast<double>(floating) / static_cast<double>(frames);
  if (contact > 0) {
    report.foot_skate_mean = skate_sum / static_cast<double>(contact);
    report.foot_skate_ratio = static_cast<double>(skating) / static_cast<double>(contact);
  }
  report.skating_ratio_gmd = GmdSkatingRatio(skeleton, joints, frames, fps, options.floor);
  if (frames >= 4) {
    double jerk_sum = 0;
    int64_t count = 0;
    for (int64_t frame = 3; frame < frames; ++frame) {
      for (int joint = 0; joint < kNumJoints; ++joint) {
        // Third finite difference: x3 - 3 x2 + 3 x1 - x0.
        const Vec3 j = at(frame, joint) - 3.0 * at(frame - 1, joint) + 3.0 * at(frame - 2, joint) -
                       at(frame - 3, joint);
        jerk_sum += Norm(j) * fps * fps * fps;
        ++count;
      }
    }
    report.jerk_mean = jerk_sum / static_cast<double>(count);
  }
  if (local) {
    for (int64_t frame = 0; frame < frames; ++frame) {
      for (int joint = 1; joint < kNumJoints; ++joint) {
        const std::string problem = CheckJointLimit(
            skeleton, joint, (*local)[static_cast<size_t>(frame * kNumJoints + joint)]);
        if (problem.empty()) continue;
        if (report.joint_limit_violations == 0)
          report.worst_joint_limit = problem + " at frame " + std::to_string(frame);
        ++report.joint_limit_violations;
      }
    }
  }
  return report;
}

PlausibilityReport EvaluateMotionPlausibility(const Skeleton& skeleton, const Motion& motion,
                                              const PlausibilityOptions& options) {
  const std::vector<float> joints = ComputeJoints(skeleton, motion);
  const std::vector<Mat3> local = LocalRotations(motion);
  return EvaluatePlausibility(skeleton, joints.data(), motion.num_frames(), motion.fps, &local,
                              options);
}

}  // namespace motionpipe
