// AMASS npz (REFERENCE.md section 1): `poses` [T, 156] (SMPL-H) or [T, 165] (SMPL-X) axis-angle
// with the root in 0:3 and the 21 body joints in 3:66, `trans` [T, 3], `betas`, `mocap_framerate`
// (SMPL-X files: `mocap_frame_rate`), `gender`. z-up, metres.
#pragma once

#include <string>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/npz.h"

namespace motionpipe {

// The first 66 pose columns as a clip at the file's frame rate. Accepts any [T, K] with K >= 66
// and K % 3 == 0 (SMPL 72, SMPL-H 156, SMPL-X 165). DataLoss names the file and the problem.
Result<Clip> AmassClipFromNpz(const Npz& npz, const std::string& origin);
// Reads and resamples by index selection to `fps` (30 for BABEL/SINC/MotionFix, 20 for HumanML3D;
// 0 keeps the file's rate).
Result<Clip> ReadAmassNpz(const std::string& path, double fps = 30);

// An AMASS-style npz for `motion`: poses [T, 156] (hand columns zero), trans, betas (16 zeros),
// mocap_framerate, gender "neutral". What the procedural corpus writes so the real loader reads it.
Npz AmassNpzFromMotion(const Motion& motion);

}  // namespace motionpipe
