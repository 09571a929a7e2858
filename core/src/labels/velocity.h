// The paper's motion-based labeling baseline (SINC sec. 3.1, Table 1 first row): a part is involved
// when its mean joint speed, standardised over the motions being labelled, is above a threshold.
#pragma once

#include <array>
#include <memory>

#include "motionpipe/labels/labeler.h"

namespace motionpipe::labels {

// Mean speeds (m/s) per part of one motion: the global part is the pelvis's world speed; the others
// are the mean speed of their joints relative to the pelvis (so that walking does not move the
// arms).
std::array<double, kNumBodyParts> PartSpeeds(const Motion& motion);

// Config: threshold (z-score, default 0.25); min_batch (below it, `absolute` m/s thresholds are
// used instead of standardising, default 20); absolute (default 0.15 m/s).
Result<std::unique_ptr<Labeler>> MakeVelocityLabeler(const nlohmann::json& config);

}  // namespace motionpipe::labels
