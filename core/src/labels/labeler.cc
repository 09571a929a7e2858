#include "motionpipe/labels/labeler.h"

#include <algorithm>
#include <cctype>
#include <sstream>
#include <unordered_map>

#include "llm.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/random.h"
#include "velocity.h"

namespace motionpipe::labels {

namespace {

std::string Clean(const std::string& s) {
  std::string out;
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (std::isalnum(u) || c == ' ') out.push_back(static_cast<char>(std::tolower(u)));
  }
  const size_t a = out.find_first_not_of(' '), b = out.find_last_not_of(' ');
  return a == std::string::npos ? "" : out.substr(a, b - a + 1);
}

uint64_t Fnv1a(const std::string& s) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (const unsigned char c : s) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

class LexiconLabeler : public Labeler {
 public:
  std::string Name() const override { return "lexicon"; }
  Result<std::vector<PartSet>> Label(const std::vector<LabelInput>& inputs) override {
    std::vector<PartSet> out;
    out.reserve(inputs.size());
    for (const auto& input : inputs) out.push_back(LexiconParts(input.text));
    return out;
  }
};

class GptAnswerLabeler : public Labeler {
 public:
  GptAnswerLabeler(GptAnswers answers, std::unique_ptr<Labeler> fallback)
      : fallback_(std::move(fallback)) {
    for (size_t k = 0; k < answers.texts.size(); ++k)
      table_[Clean(answers.texts[k])] = answers.parts[k];
  }
  std::string Name() const override { return "gpt-answers"; }
  Result<std::vector<PartSet>> Label(const std::vector<LabelInput>& inputs) override {
    std::vector<PartSet> out(inputs.size(), 0);
    std::vector<LabelInput> missing;
    std::vector<size_t> where;
    for (size_t k = 0; k < inputs.size(); ++k) {
      const auto it = table_.find(Clean(inputs[k].text));
      if (it != table_.end()) {
        out[k] = it->second;
      } else {
        missing.push_back(inputs[k]);
        where.push_back(k);
      }
    }
    if (!missing.empty()) {
      if (!fallback_) {
        return NotFound("gpt-answers: no GPT answer for '" + missing.front().text + "' (and " +
                        std::to_string(missing.size() - 1) +
                        " more); set fallback: lexicon to label them offline");
      }
      MP_ASSIGN_OR_RETURN(const std::vector<PartSet> more, fallback_->Label(missing));
      for (size_t k = 0; k < where.size(); ++k) out[where[k]] = more[k];
    }
    return out;
  }

 private:
  std::unordered_map<std::string, PartSet> table_;
  std::unique_ptr<Labeler> fallback_;
};

// The ablation: a random non-empty part set per text, fixed by the text and the seed.
class RandomLabeler : public Labeler {
 public:
  explicit RandomLabeler(uint64_t seed) : seed_(seed) {}
  std::string Name() const override { return "random"; }
  Result<std::vector<PartSet>> Label(const std::vector<LabelInput>& inputs) override {
    std::vector<PartSet> out;
    for (const auto& input : inputs) {
      Rng rng(MixSeed(seed_, Fnv1a(input.text)));
      out.push_back(static_cast<PartSet>(rng.Int(1, 63)));
    }
    return out;
  }

 private:
  uint64_t seed_;
};

}  // namespace

PartSet PartsFromGptAnswer(const std::string& answer) {
  static const std::unordered_map<std::string, PartSet> kMap = {
      {"left arm", PartBit(BodyPart::kLeftArm)},
      {"right arm", PartBit(BodyPart::kRightArm)},
      {"left leg", PartBit(BodyPart::kLeftLeg)},
      {"right leg", PartBit(BodyPart::kRightLeg)},
      {"torso", PartBit(BodyPart::kTorso)},
      {"neck", PartBit(BodyPart::kTorso)},
      {"buttocks", PartBit(BodyPart::kGlobal)},
      {"waist", PartBit(BodyPart::kGlobal)},
      {"global orientation", PartBit(BodyPart::kGlobal)},
      {"shoulders",
       static_cast<PartSet>(PartBit(BodyPart::kLeftArm) | PartBit(BodyPart::kRightArm))},
      {"left shoulder", PartBit(BodyPart::kLeftArm)},
      {"right shoulder", PartBit(BodyPart::kRightArm)},
  };
  std::string text = answer;
  // Drop the "Answer:" prefix; items are separated by lines, commas or semicolons.
  std::string lower;
  for (char c : text)
    lower.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  if (const size_t colon = lower.find("answer:"); colon != std::string::npos)
    lower = lower.substr(colon + 7);
  for (char& c : lower) {
    if (c == '\n' || c == ',' || c == ';' || c == '\r') c = '\n';
  }
  PartSet parts = 0;
  std::istringstream in(lower);
  std::string line;
  while (std::getline(in, line)) {
    const std::string item = Clean(line);
    if (const auto it = kMap.find(item); it != kMap.end()) parts |= it->second;
  }
  return parts;
}

Result<GptAnswers> LoadGptAnswers(const std::string& path, int answer) {
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(path));
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.is_object()) return DataLoss(path + ": expected a JSON object of text -> [answers]");
  GptAnswers out;
  for (const auto& item : j.items()) {
    const auto& answers = item.value();
    if (!answers.is_array() || answers.empty() || !answers.front().is_string()) {
      return DataLoss(path + ": '" + item.key() + "': expected a list of answer strings");
    }
    const size_t pick = std::min(static_cast<size_t>(std::max(answer, 0)), answers.size() - 1);
    if (!answers[pick].is_string())
      return DataLoss(path + ": '" + item.key() + "': answer " + std::to_string(pick) +
                      " is not a string");
    out.texts.push_back(item.key());
    out.parts.push_back(PartsFromGptAnswer(answers[pick].get<std::string>()));
  }
  return out;
}

bool IsHeldOut(const std::string& text, int folds) {
  return Fnv1a(text) % static_cast<uint64_t>(folds) == 0;
}

Result<std::unique_ptr<Labeler>> MakeBuiltinLabeler(const std::string& name,
                                                    const nlohmann::json& config) {
  const nlohmann::json cfg = config.is_object() ? config : nlohmann::json::object();
  if (name == "lexicon") return std::unique_ptr<Labeler>(new LexiconLabeler());
  if (name == "random")
    return std::unique_ptr<Labeler>(new RandomLabeler(cfg.value("seed", uint64_t{1})));
  if (name == "gpt-answers") {
    const std::string file =
        cfg.value("file", std::string("data/text/babel_action_labels_gpt3.json"));
    MP_ASSIGN_OR_RETURN(GptAnswers answers, LoadGptAnswers(file, cfg.value("answer", 2)));
    std::unique_ptr<Labeler> fallback;
    const std::string fallback_name = cfg.value("fallback", std::string());
    if (!fallback_name.empty()) {
      if (fallback_name == "gpt-answers")
        return InvalidArgument("gpt-answers: fallback cannot be gpt-answers");
      MP_ASSIGN_OR_RETURN(
          fallback, MakeBuiltinLabeler(fallback_name,
                                       cfg.value("fallback_config", nlohmann::json::object())));
    }
    return std::unique_ptr<Labeler>(new GptAnswerLabeler(std::move(answers), std::move(fallback)));
  }
  if (name == "velocity") return MakeVelocityLabeler(cfg);
  if (name == "llm") return MakeLlmLabeler(cfg);
  return NotFound("no built-in labeler '" + name + "'");
}

std::vector<std::string> BuiltinLabelerNames() {
  return {"gpt-answers", "lexicon", "velocity", "llm", "random"};
}

LabelerAccuracy ScoreLabels(const std::vector<LabelledText>& truth,
                            const std::vector<PartSet>& predicted) {
  LabelerAccuracy acc;
  std::array<int64_t, kNumBodyParts> right{};
  for (size_t k = 0; k < truth.size() && k < predicted.size(); ++k) {
    ++acc.texts;
    for (int p = 0; p < kNumBodyParts; ++p) {
      const float t = truth[k].truth[static_cast<size_t>(p)];
      if (t != 0.f && t != 1.f) continue;  // "sometimes": not counted (SINC Table 1)
      const bool yes = (predicted[k] >> p) & 1u;
      ++acc.counted[static_cast<size_t>(p)];
      right[static_cast<size_t>(p)] += (yes == (t == 1.f)) ? 1 : 0;
    }
  }
  double sum = 0;
  int parts = 0;
  for (int p = 0; p < kNumBodyParts; ++p) {
    const auto i = static_cast<size_t>(p);
    if (acc.counted[i] == 0) continue;
    acc.part[i] = static_cast<double>(right[i]) / static_cast<double>(acc.counted[i]);
    sum += acc.part[i];
    ++parts;
  }
  acc.mean = parts > 0 ? sum / parts : 0;
  return acc;
}

}  // namespace motionpipe::labels
