// A motion on the SMPL-22 skeleton: per-frame local joint rotations (axis-angle) and pelvis
// translation in the z-up world, at a frame rate. The in-memory twin of the clip file layout.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/math/rotation.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

struct Motion {
  double fps = 30.0;
  std::vector<float> poses;  // [T, 22, 3] axis-angle; joint 0 is the global orientation
  std::vector<float> trans;  // [T, 3] pelvis position, metres, z-up

  int64_t num_frames() const { return static_cast<int64_t>(trans.size() / 3); }
  double duration_seconds() const { return fps > 0 ? static_cast<double>(num_frames()) / fps : 0; }

  // A motion of `frames` frames in the rest pose standing upright (global orientation Rx(90)).
  static Motion Rest(int64_t frames, double fps, double pelvis_height);

  Mat3 LocalRotation(int64_t frame, int joint) const;
  void SetLocalRotation(int64_t frame, int joint, const Mat3& rotation);
  Vec3 Translation(int64_t frame) const;
  void SetTranslation(int64_t frame, const Vec3& position);
};

// Checks shapes (poses = T*66, trans = T*3, T >= min_frames), fps > 0 and that every value is
// finite. The message names `origin` and the first bad frame.
Status ValidateMotion(const Motion& motion, const std::string& origin, int64_t min_frames = 1);

// All frames' local rotation matrices, [T*22].
std::vector<Mat3> LocalRotations(const Motion& motion);

// Forward kinematics of every frame: joint positions [T, 22, 3] (float, metres, z-up).
std::vector<float> ComputeJoints(const Skeleton& skeleton, const Motion& motion);

// Frames [begin, end) of the motion.
Motion SliceFrames(const Motion& motion, int64_t begin, int64_t end);

// Resampling to another frame rate. ByIndex picks source frames, the field's convention for AMASS
// 120 -> 30 fps (numpy's arange(0, T, src/dst).astype(int): output frame i is source frame
// floor(i * src/dst)). Interpolate slerps rotations and lerps translation, for rates that do not
// divide: continuous, its velocity jumps at every source frame. Cubic runs a uniform Catmull-Rom
// spline through the source frames (Catmull and Rom 1974; the end frames repeated): on each
// joint's quaternions, every one on the hemisphere of its neighbour, renormalised, and on
// translation; it passes through the source frames and its velocity is continuous, so bringing a
// model's frames up to a higher rate adds no jerk at the frames themselves (issue 15).
enum class ResampleMethod { kByIndex, kInterpolate, kCubic };
// Rates that agree to 10 ppm are the same rate: a BVH stores 30 fps as "Frame Time: 0.03333333",
// i.e. 30.0000003 fps, which must not drop a frame. Resample keeps such a motion's frames.
bool SameFrameRate(double a, double b);
Motion Resample(const Motion& motion, double target_fps,
                ResampleMethod method = ResampleMethod::kByIndex);

// Frames at `rate` per frame at `fps` when that is a whole number k >= 1 (to 1 ppm), else 0; 1 when
// fps <= 0 or the same rate.
int64_t WholeFrameStep(double rate, double fps);
// A motion brought to a model's own rate `fps`: every k-th frame when the motion's rate is k times
// it (Resample by index, as the training data are cut), else interpolated; unchanged when fps <= 0
// or the same rate.
Motion ToModelRate(const Motion& motion, double fps);
// A model that runs at its own frame rate (the MDT's and SINC's `fps`, issue 15: fewer frames make
// a step cheaper, README "SINC at 10 fps") makes the frames at `fps` that cover `frames` frames at
// `rate` once resampled back to it: ceil((frames - 1) fps / rate) + 1 (`frames` itself when fps <=
// 0 or the same rate).
int64_t FramesCovering(int64_t frames, double rate, double fps);
// A motion made at another rate brought to `rate` (by `method`: kInterpolate or kCubic) and cut
// to exactly `frames` frames (a shorter one repeats its last frame); InvalidArgument for a motion
// without frames or for kByIndex.
Result<Motion> ResampleToFrames(const Motion& motion, double rate, int64_t frames,
                                ResampleMethod method = ResampleMethod::kInterpolate);
// The upsampling a generator's option names: "linear" (kInterpolate) or "cubic" (kCubic);
// InvalidArgument naming `origin` for anything else.
Result<ResampleMethod> ParseUpsampling(const std::string& name, const std::string& origin);

// Bounds on a resampling request, so that a mistyped rate (--fps 1e9) is an error, not an
// allocation of gigabytes: at most 1,000 fps (mocap systems record up to a few hundred) and at most
// a million output frames (9 hours at 30 fps).
inline constexpr double kMaxFrameRate = 1000;
inline constexpr int64_t kMaxResampledFrames = 1000000;
// OK when Resample(motion, target_fps) stays within those bounds (target_fps <= 0 keeps the rate);
// else InvalidArgument naming `origin`, the rate and the frames it would make.
Status CheckResample(const Motion& motion, double target_fps, const std::string& origin);

}  // namespace motionpipe
