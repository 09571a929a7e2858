// MotionFix-style editing triplets from scripts: an edit operation rewrites a source script into a
// target script and says, in the register of MotionFix's instructions, what changed. The target is
// performed by the same actor again (a jittered style), so unedited frames follow the source
// closely but never bit-exactly, as with a real actor.
#pragma once

#include <string>

#include "motionpipe/corpus/script.h"

namespace motionpipe::corpus {

enum class EditKind {
  kSpeed,
  kAmplitude,
  kSide,
  kAddAction,
  kRemoveAction,
  kReplaceAction,
  kRepetitions,
  kTiming,
  kReplaceBase,
  kPosture,
  kCount
};
const char* EditKindName(EditKind kind);

struct Edit {
  EditKind kind = EditKind::kSpeed;
  ClipScript target;
  std::string text;
  double edit_start = 0;  // seconds of the source that the edit changes
  double edit_end = 0;
};

// Picks an edit that applies to `source` and performs it. Deterministic for the rng state.
Edit SampleEdit(const ClipScript& source, Rng& rng);

}  // namespace motionpipe::corpus
