#include "motionpipe/formats/humanml3d.h"

#include <cmath>

#include "motionpipe/formats/npy.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

Result<JointSequence> ReadHumanML3DJoints(const std::string& path, double fps) {
  MP_ASSIGN_OR_RETURN(const NpyArray array, ReadNpy(path));
  if (array.shape.size() != 3 || array.shape[1] != kNumJoints || array.shape[2] != 3) {
    return DataLoss(path + ": HumanML3D joints must be [T, 22, 3], found " + array.ShapeString());
  }
  if (array.shape[0] == 0) return DataLoss(path + ": empty joint sequence");
  MP_ASSIGN_OR_RETURN(auto yup, array.ToFloat32(path));
  JointSequence seq;
  seq.fps = fps;
  seq.frames = array.shape[0];
  seq.joints.resize(yup.size());
  for (size_t k = 0; k < yup.size(); k += 3) {
    if (!std::isfinite(yup[k]) || !std::isfinite(yup[k + 1]) || !std::isfinite(yup[k + 2])) {
      return DataLoss(path + ": non-finite joint position at frame " +
                      std::to_string(k / (kNumJoints * 3)));
    }
    seq.joints[k] = yup[k];
    seq.joints[k + 1] = -yup[k + 2];
    seq.joints[k + 2] = yup[k + 1];
  }
  return seq;
}

}  // namespace motionpipe
