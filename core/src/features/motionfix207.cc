#include "motionpipe/features/motionfix207.h"

#include <cmath>

namespace motionpipe {

MotionAnchor AnchorOf(const Motion& motion) {
  if (motion.num_frames() == 0) return {};
  return {HeadingZYX(motion.LocalRotation(0, 0)), motion.Translation(0)};
}

const std::array<FeatureGroup, 5>& MotionFixFeatureGroups() {
  static const std::array<FeatureGroup, 5> groups = {{{"body_transl_delta_pelv", 0, 3},
                                                      {"body_orient_xy", 3, 9},
                                                      {"z_orient_delta", 9, 15},
                                                      {"body_pose", 15, 141},
                                                      {"body_joints_local_wo_z_rot", 141, 207}}};
  return groups;
}

FeatureMatrix EncodeMotionFix207WithJoints(const Motion& motion, const float* joints) {
  const int64_t frames = motion.num_frames();
  FeatureMatrix out(frames, kMotionFixFeatureDim);
  Mat3 prev_orient, prev_heading_rot;
  Vec3 prev_trans;
  for (int64_t frame = 0; frame < frames; ++frame) {
    float* row = out.row(frame);
    const Mat3 orient = motion.LocalRotation(frame, 0);
    const double heading = HeadingZYX(orient);
    const Mat3 heading_rot = RotZ(heading);
    const Mat3 heading_inv = Transpose(heading_rot);
    const Vec3 trans = motion.Translation(frame);
    if (frame > 0) {
      const Vec3 velocity = Transpose(prev_orient) * (trans - prev_trans);
      row[0] = static_cast<float>(velocity.x);
      row[1] = static_cast<float>(velocity.y);
      row[2] = static_cast<float>(velocity.z);
      WriteRot6d(Transpose(prev_heading_rot) * heading_rot, row + 9);
    } else {
      WriteRot6d(Mat3::Identity(), row + 9);
    }
    WriteRot6d(heading_inv * orient, row + 3);
    for (int joint = 1; joint < kNumJoints; ++joint) {
      WriteRot6d(motion.LocalRotation(frame, joint), row + 15 + (joint - 1) * 6);
    }
    const float* frame_joints = joints + frame * kNumJoints * 3;
    const Vec3 pelvis{frame_joints[0], frame_joints[1], frame_joints[2]};
    for (int joint = 0; joint < kNumJoints; ++joint) {
      const Vec3 p{frame_joints[joint * 3], frame_joints[joint * 3 + 1],
                   frame_joints[joint * 3 + 2]};
      const Vec3 local = heading_inv * (p - pelvis);
      row[141 + joint * 3 + 0] = static_cast<float>(local.x);
      row[141 + joint * 3 + 1] = static_cast<float>(local.y);
      row[141 + joint * 3 + 2] = static_cast<float>(local.z);
    }
    prev_orient = orient;
    prev_heading_rot = heading_rot;
    prev_trans = trans;
  }
  return out;
}

FeatureMatrix EncodeMotionFix207(const Skeleton& skeleton, const Motion& motion) {
  const std::vector<float> joints = ComputeJoints(skeleton, motion);
  return EncodeMotionFix207WithJoints(motion, joints.data());
}

Motion DecodeMotionFix207(const FeatureMatrix& features, const MotionAnchor& anchor, double fps) {
  const int64_t frames = features.rows;
  Motion motion;
  motion.fps = fps;
  motion.poses.resize(static_cast<size_t>(frames) * kNumJoints * 3);
  motion.trans.resize(static_cast<size_t>(frames) * 3);
  double heading = anchor.heading;
  Vec3 trans = anchor.translation;
  Mat3 prev_orient;
  for (int64_t frame = 0; frame < frames; ++frame) {
    const float* row = features.row(frame);
    if (frame > 0) {
      // Integrate the heading change as an angle so that no matrix drift accumulates.
      const Mat3 delta = ReadRot6d(row + 9);
      heading += std::atan2(delta.m[1][0], delta.m[0][0]);
      trans = trans + prev_orient * Vec3{row[0], row[1], row[2]};
    }
    const Mat3 orient = RotZ(heading) * ReadRot6d(row + 3);
    motion.SetLocalRotation(frame, 0, orient);
    motion.SetTranslation(frame, trans);
    for (int joint = 1; joint < kNumJoints; ++joint) {
      motion.SetLocalRotation(frame, joint, ReadRot6d(row + 15 + (joint - 1) * 6));
    }
    prev_orient = orient;
  }
  return motion;
}

}  // namespace motionpipe
