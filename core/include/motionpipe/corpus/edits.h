// MotionFix-style editing triplets from scripts: an edit operation rewrites a source script into a
// target script and says, in the register of MotionFix's instructions, what changed. The target is
// performed by the same actor again (a jittered style), so unedited frames follow the source
// closely but never bit-exactly, as with a real actor.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
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

// A set of edit kinds, bit (1 << kind); every kind is the corpus's default.
using EditKindSet = uint32_t;
inline constexpr EditKindSet kEveryEditKind = (1u << static_cast<int>(EditKind::kCount)) - 1;
inline bool Contains(EditKindSet kinds, EditKind kind) {
  return (kinds & (1u << static_cast<int>(kind))) != 0;
}
// Names as EditKindName prints them; an unknown name is an error that lists the known ones. An
// empty list is every kind.
Result<EditKindSet> ParseEditKinds(const std::vector<std::string>& names);
std::vector<std::string> EditKindNames(EditKindSet kinds);

struct Edit {
  EditKind kind = EditKind::kSpeed;
  ClipScript target;
  std::string text;
  double edit_start = 0;  // seconds of the source that the edit changes
  double edit_end = 0;
};

// Picks an edit of one of `kinds` that applies to `source` and performs it; nothing when no edit of
// those kinds applies, or when the one picked fell back to a kind outside them (an edit that cannot
// be performed as drawn becomes another kind). Deterministic for the rng state; with every kind it
// always returns an edit (a posture edit applies to every script).
std::optional<Edit> SampleEdit(const ClipScript& source, Rng& rng,
                               EditKindSet kinds = kEveryEditKind);

}  // namespace motionpipe::corpus
