#include "motionpipe/motion/motion.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace motionpipe {

Motion Motion::Rest(int64_t frames, double fps, double pelvis_height) {
  Motion motion;
  motion.fps = fps;
  motion.poses.assign(static_cast<size_t>(frames) * kNumJoints * 3, 0.0f);
  motion.trans.assign(static_cast<size_t>(frames) * 3, 0.0f);
  const Vec3 upright = MatrixToAxisAngle(YUpToZUp());
  for (int64_t frame = 0; frame < frames; ++frame) {
    motion.poses[static_cast<size_t>(frame) * kNumJoints * 3] = static_cast<float>(upright.x);
    motion.trans[static_cast<size_t>(frame) * 3 + 2] = static_cast<float>(pelvis_height);
  }
  return motion;
}

Mat3 Motion::LocalRotation(int64_t frame, int joint) const {
  const float* aa =
      &poses[(static_cast<size_t>(frame) * kNumJoints + static_cast<size_t>(joint)) * 3];
  return AxisAngleToMatrix({aa[0], aa[1], aa[2]});
}

void Motion::SetLocalRotation(int64_t frame, int joint, const Mat3& rotation) {
  const Vec3 aa = MatrixToAxisAngle(rotation);
  float* out = &poses[(static_cast<size_t>(frame) * kNumJoints + static_cast<size_t>(joint)) * 3];
  out[0] = static_cast<float>(aa.x);
  out[1] = static_cast<float>(aa.y);
  out[2] = static_cast<float>(aa.z);
}

Vec3 Motion::Translation(int64_t frame) const {
  const float* t = &trans[static_cast<size_t>(frame) * 3];
  return {t[0], t[1], t[2]};
}

void Motion::SetTranslation(int64_t frame, const Vec3& position) {
  float* t = &trans[static_cast<size_t>(frame) * 3];
  t[0] = static_cast<float>(position.x);
  t[1] = static_cast<float>(position.y);
  t[2] = static_cast<float>(position.z);
}

Status ValidateMotion(const Motion& motion, const std::string& origin, int64_t min_frames) {
  if (motion.trans.size() % 3 != 0) return DataLoss(origin + ": translation is not [T, 3]");
  const int64_t frames = motion.num_frames();
  if (motion.poses.size() != static_cast<size_t>(frames) * kNumJoints * 3) {
    return DataLoss(origin + ": poses hold " + std::to_string(motion.poses.size()) +
                    " values, expected T*66 = " + std::to_string(frames * kNumJoints * 3));
  }
  if (frames < min_frames) {
    return DataLoss(origin + ": " + std::to_string(frames) + " frames, need at least " +
                    std::to_string(min_frames));
  }
  if (!(motion.fps > 0) || !std::isfinite(motion.fps)) {
    return DataLoss(origin + ": frame rate must be positive, got " + std::to_string(motion.fps));
  }
  for (size_t k = 0; k < motion.poses.size(); ++k) {
    if (!std::isfinite(motion.poses[k])) {
      return DataLoss(origin + ": non-finite rotation at frame " +
                      std::to_string(k / (kNumJoints * 3)));
    }
  }
  for (size_t k = 0; k < motion.trans.size(); ++k) {
    if (!std::isfinite(motion.trans[k])) {
      return DataLoss(origin + ": non-finite translation at frame " + std::to_string(k / 3));
    }
  }
  return Status::Ok();
}

std::vector<Mat3> LocalRotations(const Motion& motion) {
  const int64_t frames = motion.num_frames();
  std::vector<Mat3> out(static_cast<size_t>(frames) * kNumJoints);
  for (int64_t frame = 0; frame < frames; ++frame) {
    for (int joint = 0; joint < kNumJoints; ++joint) {
      out[static_cast<size_t>(frame) * kNumJoints + static_cast<size_t>(joint)] =
          motion.LocalRotation(frame, joint);
    }
  }
  return out;
}

std::vector<float> ComputeJoints(const Skeleton& skeleton, const Motion& motion) {
  const int64_t frames = motion.num_frames();
  std::vector<float> joints(static_cast<size_t>(frames) * kNumJoints * 3);
  std::array<Mat3, kNumJoints> local;
  std::array<Mat3, kNumJoints> global;
  std::array<Vec3, kNumJoints> positions;
  for (int64_t frame = 0; frame < frames; ++frame) {
    for (int joint = 0; joint < kNumJoints; ++joint)
      local[static_cast<size_t>(joint)] = motion.LocalRotation(frame, joint);
    ForwardKinematicsFrame(skeleton, local.data(), motion.Translation(frame), global.data(),
                           positions.data());
    float* out = &joints[static_cast<size_t>(frame) * kNumJoints * 3];
    for (int joint = 0; joint < kNumJoints; ++joint) {
      out[joint * 3 + 0] = static_cast<float>(positions[static_cast<size_t>(joint)].x);
      out[joint * 3 + 1] = static_cast<float>(positions[static_cast<size_t>(joint)].y);
      out[joint * 3 + 2] = static_cast<float>(positions[static_cast<size_t>(joint)].z);
    }
  }
  return joints;
}

Motion SliceFrames(const Motion& motion, int64_t begin, int64_t end) {
  begin = std::clamp<int64_t>(begin, 0, motion.num_frames());
  end = std::clamp<int64_t>(end, begin, motion.num_frames());
  Motion out;
  out.fps = motion.fps;
  const size_t pose_stride = kNumJoints * 3;
  out.poses.assign(
      motion.poses.begin() + static_cast<std::ptrdiff_t>(static_cast<size_t>(begin) * pose_stride),
      motion.poses.begin() + static_cast<std::ptrdiff_t>(static_cast<size_t>(end) * pose_stride));
  out.trans.assign(motion.trans.begin() + begin * 3, motion.trans.begin() + end * 3);
  return out;
}

namespace {

// The uniform Catmull-Rom segment between p1 (t = 0) and p2 (t = 1), tangents (p2 - p0) / 2 and
// (p3 - p1) / 2.
double CatmullRom(double p0, double p1, double p2, double p3, double t) {
  return p1 +
         0.5 * t *
             ((p2 - p0) + t * ((2 * p0 - 5 * p1 + 4 * p2 - p3) + t * (3 * (p1 - p2) + p3 - p0)));
}

// q or -q (the same rotation), whichever lies on the hemisphere of `near`.
Quat SameHemisphere(const Quat& q, const Quat& near) {
  const double dot = q.w * near.w + q.x * near.x + q.y * near.y + q.z * near.z;
  return dot < 0 ? Quat{-q.w, -q.x, -q.y, -q.z} : q;
}

std::string Rate(double fps) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", fps);
  return text;
}

}  // namespace

Status CheckResample(const Motion& motion, double target_fps, const std::string& origin) {
  if (std::isnan(target_fps) || target_fps > kMaxFrameRate) {
    return InvalidArgument(
        origin + ": a frame rate of " + Rate(target_fps) + " fps is out of range (at most " +
        std::to_string(static_cast<int>(kMaxFrameRate)) + "; 0 keeps the file's)");
  }
  if (target_fps <= 0 || motion.num_frames() == 0 || !(motion.fps > 0)) return Status::Ok();
  const double frames = static_cast<double>(motion.num_frames() - 1) * target_fps / motion.fps + 1;
  if (frames > static_cast<double>(kMaxResampledFrames)) {
    return InvalidArgument(origin + ": resampling " + std::to_string(motion.num_frames()) +
                           " frames from " + Rate(motion.fps) + " to " + Rate(target_fps) +
                           " fps would make " + std::to_string(static_cast<int64_t>(frames)) +
                           " frames (at most " + std::to_string(kMaxResampledFrames) + ")");
  }
  return Status::Ok();
}

bool SameFrameRate(double a, double b) { return std::abs(a - b) <= 1e-5 * std::max(a, b); }

Motion Resample(const Motion& motion, double target_fps, ResampleMethod method) {
  const int64_t frames = motion.num_frames();
  if (frames == 0 || target_fps <= 0 || SameFrameRate(target_fps, motion.fps)) {
    Motion same = motion;
    if (target_fps > 0) same.fps = target_fps;
    return same;
  }
  const double step = motion.fps / target_fps;  // source frames per output frame
  // Output frames cover the same duration: the last output frame maps inside the source.
  const int64_t out_frames =
      std::max<int64_t>(1, static_cast<int64_t>(std::floor((frames - 1) / step + 1e-6)) + 1);
  Motion out;
  out.fps = target_fps;
  out.poses.resize(static_cast<size_t>(out_frames) * kNumJoints * 3);
  out.trans.resize(static_cast<size_t>(out_frames) * 3);
  for (int64_t frame = 0; frame < out_frames; ++frame) {
    const double src = static_cast<double>(frame) * step;
    if (method == ResampleMethod::kByIndex) {
      const int64_t index =
          std::min<int64_t>(frames - 1, static_cast<int64_t>(std::floor(src + 1e-9)));
      std::copy_n(&motion.poses[static_cast<size_t>(index) * kNumJoints * 3], kNumJoints * 3,
                  &out.poses[static_cast<size_t>(frame) * kNumJoints * 3]);
      std::copy_n(&motion.trans[static_cast<size_t>(index) * 3], 3,
                  &out.trans[static_cast<size_t>(frame) * 3]);
      continue;
    }
    const int64_t lo = std::min<int64_t>(frames - 1, static_cast<int64_t>(std::floor(src)));
    const int64_t hi = std::min<int64_t>(frames - 1, lo + 1);
    const double t = src - static_cast<double>(lo);
    if (method == ResampleMethod::kCubic) {
      const int64_t before = std::max<int64_t>(0, lo - 1);
      const int64_t after = std::min<int64_t>(frames - 1, hi + 1);
      for (int joint = 0; joint < kNumJoints; ++joint) {
        const Quat q1 = MatrixToQuat(motion.LocalRotation(lo, joint));
        const Quat q0 = SameHemisphere(MatrixToQuat(motion.LocalRotation(before, joint)), q1);
        const Quat q2 = SameHemisphere(MatrixToQuat(motion.LocalRotation(hi, joint)), q1);
        const Quat q3 = SameHemisphere(MatrixToQuat(motion.LocalRotation(after, joint)), q2);
        const Quat q = {
            CatmullRom(q0.w, q1.w, q2.w, q3.w, t), CatmullRom(q0.x, q1.x, q2.x, q3.x, t),
            CatmullRom(q0.y, q1.y, q2.y, q3.y, t), CatmullRom(q0.z, q1.z, q2.z, q3.z, t)};
        out.SetLocalRotation(frame, joint, QuatToMatrix(Normalized(q)));
      }
      const Vec3 p0 = motion.Translation(before), p1 = motion.Translation(lo),
                 p2 = motion.Translation(hi), p3 = motion.Translation(after);
      out.SetTranslation(
          frame, {CatmullRom(p0.x, p1.x, p2.x, p3.x, t), CatmullRom(p0.y, p1.y, p2.y, p3.y, t),
                  CatmullRom(p0.z, p1.z, p2.z, p3.z, t)});
      continue;
    }
    for (int joint = 0; joint < kNumJoints; ++joint) {
      const Quat a = MatrixToQuat(motion.LocalRotation(lo, joint));
      const Quat b = MatrixToQuat(motion.LocalRotation(hi, joint));
      out.SetLocalRotation(frame, joint, QuatToMatrix(Slerp(a, b, t)));
    }
    const Vec3 pa = motion.Translation(lo), pb = motion.Translation(hi);
    out.SetTranslation(frame, (1 - t) * pa + t * pb);
  }
  return out;
}

int64_t WholeFrameStep(double rate, double fps) {
  if (fps <= 0 || SameFrameRate(rate, fps)) return 1;
  const double ratio = rate / fps;
  const double whole = std::round(ratio);
  return whole >= 1 && std::abs(ratio - whole) <= 1e-6 * whole ? static_cast<int64_t>(whole) : 0;
}

Motion ToModelRate(const Motion& motion, double fps) {
  if (fps <= 0 || SameFrameRate(motion.fps, fps)) return motion;
  return Resample(motion, fps,
                  WholeFrameStep(motion.fps, fps) > 0 ? ResampleMethod::kByIndex
                                                      : ResampleMethod::kInterpolate);
}

int64_t FramesCovering(int64_t frames, double rate, double fps) {
  if (fps <= 0 || !(rate > 0) || SameFrameRate(rate, fps)) return frames;
  return static_cast<int64_t>(std::ceil(static_cast<double>(frames - 1) * fps / rate - 1e-9)) + 1;
}

Result<Motion> ResampleToFrames(const Motion& motion, double rate, int64_t frames,
                                ResampleMethod method) {
  if (motion.num_frames() == 0) return InvalidArgument("resampling a motion without frames");
  if (method == ResampleMethod::kByIndex)
    return InvalidArgument("resampling to a number of frames interpolates (linear or cubic)");
  // Resample keeps a motion already at `rate` (SameFrameRate) as it is.
  Motion out = Resample(motion, rate, method);
  out.fps = rate;
  // Resample covers the same duration, so it gives at least `frames` frames from FramesCovering's;
  // a shorter motion (another length) repeats its last frame.
  const int64_t have = out.num_frames();
  out.poses.resize(static_cast<size_t>(frames) * kNumJoints * 3);
  out.trans.resize(static_cast<size_t>(frames) * 3);
  for (int64_t f = have; f < frames; ++f) {
    std::copy_n(&out.poses[static_cast<size_t>(have - 1) * kNumJoints * 3], kNumJoints * 3,
                &out.poses[static_cast<size_t>(f) * kNumJoints * 3]);
    std::copy_n(&out.trans[static_cast<size_t>(have - 1) * 3], 3,
                &out.trans[static_cast<size_t>(f) * 3]);
  }
  return out;
}

Result<ResampleMethod> ParseUpsampling(const std::string& name, const std::string& origin) {
  if (name == "linear") return ResampleMethod::kInterpolate;
  if (name == "cubic") return ResampleMethod::kCubic;
  return InvalidArgument(origin + " must be linear or cubic (got '" + name + "')");
}

}  // namespace motionpipe
