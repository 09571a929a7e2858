#include "motionpipe/features/temos135.h"

#include <cmath>
#include <cstring>
#include <vector>

#include "../simd/simd.h"

namespace motionpipe {

FeatureMatrix EncodeTemos135(const Motion& motion, double canonical_heading) {
  const int64_t frames = motion.num_frames();
  FeatureMatrix out(frames, kTemosFeatureDim);
  if (frames == 0) return out;
  // Turn the whole motion about z so the first heading becomes canonical (SINC sec. 4.5).
  const Mat3 canon = RotZ(canonical_heading - HeadingZYX(motion.LocalRotation(0, 0)));
  Vec3 prev;
  for (int64_t frame = 0; frame < frames; ++frame) {
    float* row = out.row(frame);
    const Vec3 trans = canon * motion.Translation(frame);
    row[0] = static_cast<float>(trans.z);
    if (frame > 0) {
      row[1] = static_cast<float>(trans.x - prev.x);
      row[2] = static_cast<float>(trans.y - prev.y);
    }
    WriteRot6d(canon * motion.LocalRotation(frame, 0), row + 3);
    for (int joint = 1; joint < kNumJoints; ++joint)
      WriteRot6d(motion.LocalRotation(frame, joint), row + 3 + joint * 6);
    prev = trans;
  }
  return out;
}

void EncodeTemos135FastJoints(const float* const* joint_poses, const float* trans, int64_t frames,
                              float* out, double canonical_heading) {
  if (frames <= 0) return;
  const int64_t n = frames;
  // Each distinct source motion (one, or two for a composition) is transposed whole into
  // joint-major planes [(3 j + a) T + f] (8 x 8 register blocks); each joint then reads its own
  // source's planes.
  const float* sources[kNumJoints];
  int num_sources = 0;
  int source_of[kNumJoints];
  for (int j = 0; j < kNumJoints; ++j) {
    int s = 0;
    while (s < num_sources && sources[s] != joint_poses[j]) ++s;
    if (s == num_sources) sources[num_sources++] = joint_poses[j];
    source_of[j] = s;
  }
  thread_local std::vector<float> scratch;
  scratch.resize(static_cast<size_t>(n * (3 * kNumJoints * num_sources + 6 * kNumJoints)));
  float* six = scratch.data();             // [(6 j + k) T + f]
  float* axis = six + 6 * kNumJoints * n;  // per source: [(3 j + a) T + f]
  for (int s = 0; s < num_sources; ++s)
    simd::Transpose(sources[s], 3 * kNumJoints, n, 3 * kNumJoints, axis + s * 3 * kNumJoints * n,
                    n);
  for (int j = 0; j < kNumJoints; ++j) {
    const float* a = axis + source_of[j] * 3 * kNumJoints * n + 3 * j * n;
    simd::AxisAngleToMatrices(a, a + n, a + 2 * n, n, six + 6 * j * n, n, 2);
  }
  // The whole motion turns about z so that the first heading is canonical (SINC sec. 4.5); on the
  // root's two rows that is (c r0 - s r1, s r0 + c r1).
  const float* root0 = joint_poses[0];
  const Mat3 r0 = AxisAngleToMatrix({root0[0], root0[1], root0[2]});
  const double angle = canonical_heading - HeadingZYX(r0);
  const double c = std::cos(angle), s = std::sin(angle);
  const auto cf = static_cast<float>(c), sf = static_cast<float>(s);
  for (int k = 0; k < 3; ++k) {
    float* row0 = six + k * n;
    float* row1 = six + (3 + k) * n;
    for (int64_t f = 0; f < n; ++f) {
      const float a0 = row0[f], a1 = row1[f];
      row0[f] = cf * a0 - sf * a1;
      row1[f] = sf * a0 + cf * a1;
    }
  }
  simd::Transpose(six, n, 6 * kNumJoints, n, out + 3, kTemosFeatureDim);
  // Height and planar velocity of the turned trajectory, in double.
  double px = 0, py = 0;
  for (int64_t f = 0; f < n; ++f) {
    const double x = trans[3 * f], y = trans[3 * f + 1];
    const double tx = c * x - s * y, ty = s * x + c * y;
    float* row = out + f * kTemosFeatureDim;
    row[0] = trans[3 * f + 2];
    row[1] = f > 0 ? static_cast<float>(tx - px) : 0.f;
    row[2] = f > 0 ? static_cast<float>(ty - py) : 0.f;
    px = tx, py = ty;
  }
}

void EncodeTemos135Fast(const float* poses, const float* trans, int64_t frames, float* out,
                        double canonical_heading) {
  const float* joints[kNumJoints];
  for (auto& p : joints) p = poses;
  EncodeTemos135FastJoints(joints, trans, frames, out, canonical_heading);
}

int64_t EveryKthTemos135(const float* features, int64_t frames, int64_t k, float* out) {
  if (frames <= 0) return 0;
  const int64_t rows = (frames - 1) / k + 1;
  for (int64_t g = 0; g < rows; ++g) {
    // Rows (g - 1) k + 1 .. g k are read before row g is written; every earlier output row is
    // below them, so `out` may be `features`.
    double vx = 0, vy = 0;
    for (int64_t f = (g - 1) * k + 1; g > 0 && f <= g * k; ++f) {
      vx += features[f * kTemosFeatureDim + 1];
      vy += features[f * kTemosFeatureDim + 2];
    }
    const float* from = features + g * k * kTemosFeatureDim;
    float* row = out + g * kTemosFeatureDim;
    if (row != from) std::memmove(row, from, sizeof(float) * kTemosFeatureDim);
    row[1] = static_cast<float>(vx);
    row[2] = static_cast<float>(vy);
  }
  return rows;
}

Motion DecodeTemos135(const FeatureMatrix& features, const MotionAnchor& anchor, double fps,
                      double canonical_heading) {
  const int64_t frames = features.rows;
  Motion motion;
  motion.fps = fps;
  motion.poses.resize(static_cast<size_t>(frames) * kNumJoints * 3);
  motion.trans.resize(static_cast<size_t>(frames) * 3);
  const Mat3 uncanon = RotZ(anchor.heading - canonical_heading);
  // Trajectory in the canonical frame, starting at the origin; accumulated in double.
  double x = 0, y = 0;
  for (int64_t frame = 0; frame < frames; ++frame) {
    const float* row = features.row(frame);
    if (frame > 0) {
      x += row[1];
      y += row[2];
    }
    const Vec3 turned = uncanon * Vec3{x, y, 0};
    motion.SetTranslation(
        frame, {anchor.translation.x + turned.x, anchor.translation.y + turned.y, row[0]});
    motion.SetLocalRotation(frame, 0, uncanon * ReadRot6d(row + 3));
    for (int joint = 1; joint < kNumJoints; ++joint)
      motion.SetLocalRotation(frame, joint, ReadRot6d(row + 3 + joint * 6));
  }
  return motion;
}

MotionAnchor CanonicalTemosAnchor(double canonical_heading) {
  return {canonical_heading, {0, 0, 0}};
}

}  // namespace motionpipe
