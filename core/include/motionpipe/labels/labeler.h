// Body-part labelers (SINC sec. 3.1, REFERENCE 4.1): which of the six parts [global, torso, left
// arm, right arm, left leg, right leg] an action uses. Built in: `gpt-answers` (SINC's own GPT-3
// answers, mapped with its rules), `lexicon` (offline rules over verbs, body nouns, sides, plurals,
// negation), `velocity` (the paper's motion-based baseline), `llm` (an OpenAI-compatible endpoint
// with the paper's few-shot prompt) and `random` (the ablation). Plugins add more through factories
// of kind "labeler" (the `learned` classifier lives in plugins/labelers on LibTorch).
#pragma once

#include <array>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::labels {

struct LabelInput {
  std::string text;
  const Motion* motion = nullptr;  // needed by motion-based labelers (velocity)
};

class Labeler {
 public:
  virtual ~Labeler() = default;
  virtual std::string Name() const = 0;
  virtual bool NeedsMotion() const { return false; }
  // One part set per input, in order. A labeler that cannot answer for an input (no GPT answer for
  // the text, a network failure after retries) returns an error naming the input.
  virtual Result<std::vector<PartSet>> Label(const std::vector<LabelInput>& inputs) = 0;
};

// A built-in labeler by name with its JSON configuration; NotFound for unknown names (the plugin
// host is asked next).
Result<std::unique_ptr<Labeler>> MakeBuiltinLabeler(const std::string& name,
                                                    const nlohmann::json& config);
std::vector<std::string> BuiltinLabelerNames();

// ---- SINC's GPT answers ----------------------------------------------------------------------

// One raw answer ("Answer: right arm\nleft arm\nneck") to parts, with SINC's mapping: buttocks and
// waist -> global, neck -> torso, shoulders -> both arms, left/right shoulder -> that arm; words
// for hands, wrists, eyes and faces (and anything else) are dropped.
PartSet PartsFromGptAnswer(const std::string& answer);

struct GptAnswers {
  std::vector<std::string> texts;
  std::vector<PartSet> parts;
};
// The answers file (text -> [answer, answer, answer]); `answer` picks which (SINC uses the third,
// 2).
Result<GptAnswers> LoadGptAnswers(const std::string& path, int answer = 2);

// The evaluation split of labelled texts: a stable hash puts one text in `folds` into held-out.
bool IsHeldOut(const std::string& text, int folds = 5);

// ---- the offline lexicon ---------------------------------------------------------------------

// Rules: body nouns (arm/hand/elbow..., leg/foot/knee..., head/neck/chest..., hips/waist...) with
// their side ("left hand", "both arms", plural = both), verbs with their usual parts (walk -> legs
// + global, wave -> arms, nod -> torso, ...), synonyms, and negation ("without moving the arms",
// "keep legs still") removing parts. Nouns decide a limb's side over a verb's default.
PartSet LexiconParts(const std::string& text);

// ---- evaluation ------------------------------------------------------------------------------

// Ground truth per part: 1 (yes), 0 (no), anything in between = "sometimes" (ignored).
struct LabelledText {
  std::string text;
  std::array<float, kNumBodyParts> truth{};
  const Motion* motion = nullptr;
};

struct LabelerAccuracy {
  std::array<double, kNumBodyParts> part{};  // accuracy per part over the decided values
  std::array<int64_t, kNumBodyParts> counted{};
  double mean = 0;  // mean of the six part accuracies (SINC Table 1)
  int64_t texts = 0;
};

LabelerAccuracy ScoreLabels(const std::vector<LabelledText>& truth,
                            const std::vector<PartSet>& predicted);

}  // namespace motionpipe::labels
