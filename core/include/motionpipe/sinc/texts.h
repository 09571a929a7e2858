// SINC's text augmentation for pairs of simultaneous actions (paper sec. 3.2, REFERENCE 4.3): the
// two labels in random order, joined by one of five patterns; the second action takes its gerund
// where the pattern needs one ("wave right hand" -> "waving right hand", "sits down" -> "sitting
// down", "a person lies down" -> "lying down"). Evaluation always uses "while".
#pragma once

#include <string>

#include "motionpipe/base/random.h"

namespace motionpipe::sinc {

enum class PairPattern : uint8_t {
  kWhile = 0,       // "A while B-ing"
  kSimultaneously,  // "simultaneously A and B"
  kComma,           // "A, B"
  kAtTheSameTime,   // "A and B at the same time"
  kDuring,          // "A during B-ing"
};
inline constexpr int kNumPairPatterns = 5;

// The verb phrase of a label, for the gerund: the subject of a sentence ("a person", "someone",
// "he", ...) and auxiliaries ("is", "are") go; a third-person verb returns to its base form
// ("swings" -> "swing", "reaches" -> "reach", "tries" -> "try", "goes" -> "go").
std::string VerbPhrase(const std::string& label);
// The -ing form of the label's verb phrase ("swings arms forward" -> "swinging arms forward").
std::string GerundOfLabel(const std::string& label);

// One pattern applied to (first, second), in that order.
std::string PairText(const std::string& first, const std::string& second, PairPattern pattern);
// Training augmentation: order and pattern drawn from `rng` (reported through the pointers).
std::string AugmentPairText(const std::string& a, const std::string& b, Rng& rng,
                            PairPattern* pattern = nullptr, bool* swapped = nullptr);
// Evaluation: "a while b-ing".
inline std::string EvalPairText(const std::string& a, const std::string& b) {
  return PairText(a, b, PairPattern::kWhile);
}

}  // namespace motionpipe::sinc
