#include "motionpipe/formats/amass.h"

#include <algorithm>
#include <cmath>

namespace motionpipe {

Result<Clip> AmassClipFromNpz(const Npz& npz, const std::string& origin) {
  MP_ASSIGN_OR_RETURN(const NpyArray* poses_a, npz.Get("poses", origin));
  if (poses_a->shape.size() != 2 || poses_a->shape[1] < kNumJoints * 3 ||
      poses_a->shape[1] % 3 != 0) {
    return DataLoss(
        origin + ": 'poses' has shape " + poses_a->ShapeString() +
        ", expected [T, 156] (SMPL-H), [T, 165] (SMPL-X) or another [T, 3K] with K >= 22");
  }
  const int64_t frames = poses_a->shape[0];
  const int64_t cols = poses_a->shape[1];
  MP_ASSIGN_OR_RETURN(const NpyArray* trans_a, GetShaped(npz, "trans", {frames, 3}, origin));
  const NpyArray* rate_a = npz.Find("mocap_framerate");
  if (!rate_a) rate_a = npz.Find("mocap_frame_rate");
  if (!rate_a) return DataLoss(origin + ": no 'mocap_framerate' (or 'mocap_frame_rate')");
  if (rate_a->num_elements() != 1) return DataLoss(origin + ": frame rate is not a scalar");
  MP_ASSIGN_OR_RETURN(auto rate, rate_a->ToFloat64(origin + ": frame rate"));
  MP_ASSIGN_OR_RETURN(auto poses, poses_a->ToFloat32(origin + ": 'poses'"));
  MP_ASSIGN_OR_RETURN(auto trans, trans_a->ToFloat32(origin + ": 'trans'"));
  Clip clip;
  clip.source = "amass:" + origin;
  clip.motion.fps = rate.front();
  clip.motion.trans = std::move(trans);
  clip.motion.poses.resize(static_cast<size_t>(frames) * kNumJoints * 3);
  for (int64_t frame = 0; frame < frames; ++frame) {
    std::copy_n(poses.begin() + frame * cols, kNumJoints * 3,
                clip.motion.poses.begin() + frame * kNumJoints * 3);
  }
  MP_RETURN_IF_ERROR(ValidateClip(clip, origin));
  return clip;
}

Result<Clip> ReadAmassNpz(const std::string& path, double fps) {
  MP_ASSIGN_OR_RETURN(const Npz npz, ReadNpz(path));
  MP_ASSIGN_OR_RETURN(Clip clip, AmassClipFromNpz(npz, path));
  MP_RETURN_IF_ERROR(CheckResample(clip.motion, fps, path));
  if (fps > 0) clip.motion = Resample(clip.motion, fps);
  return clip;
}

Npz AmassNpzFromMotion(const Motion& motion) {
  const int64_t frames = motion.num_frames();
  constexpr int64_t kSmplhColumns = 156;
  std::vector<float> poses(static_cast<size_t>(frames * kSmplhColumns), 0.0f);
  for (int64_t frame = 0; frame < frames; ++frame) {
    std::copy_n(motion.poses.begin() + frame * kNumJoints * 3, kNumJoints * 3,
                poses.begin() + frame * kSmplhColumns);
  }
  Npz npz;
  npz.Add("poses", NpyArray::Float32({frames, kSmplhColumns}, poses));
  npz.Add("trans", NpyArray::Float32({frames, 3}, motion.trans));
  npz.Add("betas", NpyArray::Float32({16}, std::vector<float>(16, 0.0f)));
  npz.Add("mocap_framerate", NpyArray::ScalarFloat64(motion.fps));
  npz.Add("gender", NpyArray::ScalarString("neutral"));
  return npz;
}

}  // namespace motionpipe
