#include "motionpipe/features/temos135.h"

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
    for (int joint = 1; joint < kNumJoints; ++joint) WriteRot6d(motion.LocalRotation(frame, joint), row + 3 + joint * 6);
    prev = trans;
  }
  return out;
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
    motion.SetTranslation(frame, {anchor.translation.x + turned.x, anchor.translation.y + turned.y, row[0]});
    motion.SetLocalRotation(frame, 0, uncanon * ReadRot6d(row + 3));
    for (int joint = 1; joint < kNumJoints; ++joint) motion.SetLocalRotation(frame, joint, ReadRot6d(row + 3 + joint * 6));
  }
  return motion;
}

MotionAnchor CanonicalTemosAnchor(double canonical_heading) { return {canonical_heading, {0, 0, 0}}; }

}  // namespace motionpipe
