// `motionpipe labels ...`: body-part labels for action texts (SINC sec. 3.1) and the accuracy table
// of SINC Table 1 for any labeler.
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "commands.h"
#include "labelers.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/clip.h"

namespace motionpipe::cli {

namespace {

Result<nlohmann::json> ParseConfig(const std::string& text) {
  if (text.empty()) return nlohmann::json::object();
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.is_object())
    return InvalidArgument("--config: expected a JSON object, e.g. '{\"fallback\": \"lexicon\"}'");
  return j;
}

worker::PluginHost& Plugins() {
  static worker::PluginHost host = [] {
    worker::PluginHost h;
    for (const std::string& dir : worker::DefaultPluginDirs()) h.LoadDirectory(dir);
    return h;
  }();
  return host;
}

// The GPT-labelled texts of SINC's answers file (third answer, binary truth), one split of them.
Result<std::vector<labels::LabelledText>> GptTruth(const std::string& path,
                                                   const std::string& split) {
  MP_ASSIGN_OR_RETURN(const labels::GptAnswers answers, labels::LoadGptAnswers(path, 2));
  std::vector<labels::LabelledText> out;
  for (size_t k = 0; k < answers.texts.size(); ++k) {
    const bool held_out = labels::IsHeldOut(answers.texts[k]);
    if ((split == "heldout" && !held_out) || (split == "train" && held_out)) continue;
    labels::LabelledText t;
    t.text = answers.texts[k];
    for (int p = 0; p < kNumBodyParts; ++p)
      t.truth[static_cast<size_t>(p)] = ((answers.parts[k] >> p) & 1u) ? 1.f : 0.f;
    out.push_back(std::move(t));
  }
  return out;
}

// The corpus's texts with their known parts (texts/labels.json: fractions; in-between =
// "sometimes").
Result<std::vector<labels::LabelledText>> CorpusTextTruth(const std::string& dir) {
  const std::string path = dir + "/texts/labels.json";
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(path));
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.is_object() || !j.contains("labels") || !j["labels"].is_object())
    return DataLoss(path + ": expected {\"labels\": {...}}");
  std::vector<labels::LabelledText> out;
  for (const auto& item : j["labels"].items()) {
    const auto& parts = item.value().at("parts");
    if (!parts.is_array() || parts.size() != kNumBodyParts)
      return DataLoss(path + ": '" + item.key() + "': parts must have 6 values");
    labels::LabelledText t;
    t.text = item.key();
    for (int p = 0; p < kNumBodyParts; ++p)
      t.truth[static_cast<size_t>(p)] = parts[static_cast<size_t>(p)].get<float>();
    out.push_back(std::move(t));
  }
  return out;
}

// The corpus's labelled segments with their motions (for motion-based labelers): exact parts.
struct SegmentTruth {
  std::vector<Motion> motions;
  std::vector<labels::LabelledText> truth;
};
Result<SegmentTruth> CorpusSegmentTruth(const std::string& dir, size_t limit) {
  SegmentTruth out;
  std::vector<std::string> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir + "/clips", ec))
    files.push_back(entry.path().string());
  if (ec) return NotFound(dir + "/clips: " + ec.message());
  std::sort(files.begin(), files.end());
  for (const std::string& file : files) {
    MP_ASSIGN_OR_RETURN(const std::vector<Clip> clips, ReadClips(file));
    for (const Clip& clip : clips) {
      for (const Segment& seg : clip.segments) {
        if (out.motions.size() >= limit) break;
        if (seg.end_frame - seg.start_frame < 15 || seg.parts == 0) continue;
        out.motions.push_back(SliceFrames(clip.motion, seg.start_frame, seg.end_frame));
        labels::LabelledText t;
        t.text = seg.text;
        for (int p = 0; p < kNumBodyParts; ++p)
          t.truth[static_cast<size_t>(p)] = ((seg.parts >> p) & 1u) ? 1.f : 0.f;
        out.truth.push_back(std::move(t));
      }
    }
  }
  for (size_t k = 0; k < out.truth.size(); ++k) out.truth[k].motion = &out.motions[k];
  return out;
}

void PrintRow(const std::string& labeler, const std::string& data,
              const labels::LabelerAccuracy& acc) {
  std::printf("%-14s %-26s %6lld", labeler.c_str(), data.c_str(),
              static_cast<long long>(acc.texts));
  for (const double a : acc.part) std::printf(" %7.3f", a);
  std::printf(" %7.3f\n", acc.mean);
}

// "gpt-answers, lexicon, velocity, llm, random": the built-in labelers, for the help texts.
std::string BuiltInLabelers() {
  std::string names;
  for (const std::string& name : labels::BuiltinLabelerNames())
    names += (names.empty() ? "" : ", ") + name;
  return names;
}

// ---- labels label ------------------------------------------------------------------------------
struct LabelArgs {
  std::string name = "lexicon", config_text;
  std::vector<std::string> texts;
};

int RunLabel(const LabelArgs& a) {
  auto config = ParseConfig(a.config_text);
  if (!config.ok()) return Usage(config.status().message());
  auto labeler = worker::MakeLabeler(a.name, *config, &Plugins());
  if (!labeler.ok()) return Fail(labeler.status());
  std::vector<labels::LabelInput> inputs;
  for (const auto& t : a.texts) inputs.push_back({t, nullptr});
  auto parts = (*labeler)->Label(inputs);
  if (!parts.ok()) return Fail(parts.status());
  for (size_t k = 0; k < a.texts.size(); ++k)
    std::printf("%-40s %s\n", a.texts[k].c_str(), PartSetToString((*parts)[k]).c_str());
  return kExitOk;
}

void AddLabel(CLI::App* group, int* exit_code) {
  auto* cmd = group->add_subcommand("label", "Print the body parts a labeler gives each text");
  static LabelArgs a;
  cmd->add_option("--labeler", a.name, BuiltInLabelers() + ", or a plugin's (learned)")
      ->capture_default_str();
  cmd->add_option("--config", a.config_text, "The labeler's configuration as JSON");
  cmd->add_option("texts", a.texts, "Action texts")->required();
  cmd->callback([exit_code] { *exit_code = RunLabel(a); });
}

// ---- labels eval -------------------------------------------------------------------------------
struct EvalArgs {
  std::vector<std::string> names;
  std::string config_text, gpt_file = "data/text/babel_action_labels_gpt3.json";
  std::string split = "heldout", corpus;
  size_t segments = 2000;
  int show_errors = 0;
};

// The data sets a labeler is scored on: the GPT answers' split, the corpus's texts and segments.
struct EvalData {
  std::vector<labels::LabelledText> gpt, corpus_texts;
  SegmentTruth corpus_segments;
};

Result<EvalData> LoadEvalData(const EvalArgs& a) {
  EvalData data;
  if (a.split != "none") {
    MP_ASSIGN_OR_RETURN(data.gpt, GptTruth(a.gpt_file, a.split));
  }
  if (!a.corpus.empty()) {
    MP_ASSIGN_OR_RETURN(data.corpus_texts, CorpusTextTruth(a.corpus));
    MP_ASSIGN_OR_RETURN(data.corpus_segments, CorpusSegmentTruth(a.corpus, a.segments));
  }
  return data;
}

// One row of the table (and up to `show_errors` disagreements): `labeler` on `truth`.
Status ScoreOn(labels::Labeler& labeler, const std::string& name,
               const std::vector<labels::LabelledText>& truth, const std::string& data,
               int show_errors) {
  if (truth.empty()) return Status::Ok();
  std::vector<labels::LabelInput> inputs;
  for (const auto& t : truth) inputs.push_back({t.text, t.motion});
  MP_ASSIGN_OR_RETURN(const std::vector<PartSet> parts, labeler.Label(inputs));
  PrintRow(name, data, labels::ScoreLabels(truth, parts));
  int shown = 0;
  for (size_t k = 0; k < truth.size() && shown < show_errors; ++k) {
    PartSet want = 0, mask = 0;
    for (int p = 0; p < kNumBodyParts; ++p) {
      const float t = truth[k].truth[static_cast<size_t>(p)];
      if (t == 1.f) want |= static_cast<PartSet>(1u << p);
      if (t == 0.f || t == 1.f) mask |= static_cast<PartSet>(1u << p);
    }
    if ((parts[k] & mask) == want) continue;
    ++shown;
    std::printf("    %-50s truth %-40s got %s\n", truth[k].text.c_str(),
                PartSetToString(want).c_str(), PartSetToString(parts[k]).c_str());
  }
  return Status::Ok();
}

int RunEval(const EvalArgs& a) {
  auto config = ParseConfig(a.config_text);
  if (!config.ok()) return Usage(config.status().message());
  auto data = LoadEvalData(a);
  if (!data.ok()) return Fail(data.status());
  const std::vector<std::string> names =
      a.names.empty() ? std::vector<std::string>{"lexicon"} : a.names;
  std::printf("%-14s %-26s %6s %7s %7s %7s %7s %7s %7s %7s\n", "labeler", "data", "n", "global",
              "torso", "l.arm", "r.arm", "l.leg", "r.leg", "mean");
  int code = kExitOk;
  for (const std::string& name : names) {
    auto labeler = worker::MakeLabeler(name, *config, &Plugins());
    if (!labeler.ok()) {
      code = Fail(labeler.status());
      continue;
    }
    std::vector<std::pair<const std::vector<labels::LabelledText>*, std::string>> sets;
    if ((*labeler)->NeedsMotion()) {
      sets = {{&data->corpus_segments.truth, "corpus segments (motion)"}};
    } else {
      sets = {{&data->gpt, "GPT-3 answers (" + a.split + ")"},
              {&data->corpus_texts, "corpus texts"},
              {&data->corpus_segments.truth, "corpus segments (text)"}};
    }
    for (const auto& [truth, label] : sets) {
      if (Status s = ScoreOn(**labeler, name, *truth, label, a.show_errors); !s.ok())
        code = Fail(s);
    }
  }
  return code;
}

void AddEval(CLI::App* group, int* exit_code) {
  auto* cmd = group->add_subcommand("eval",
                                    "Per-part and mean accuracy (SINC Table 1: Yes/No counted, "
                                    "'sometimes' ignored) of labelers");
  static EvalArgs a;
  cmd->add_option(
      "--labeler", a.names,
      "Labelers to score (repeat; default lexicon): " + BuiltInLabelers() + ", or a plugin's");
  cmd->add_option("--config", a.config_text, "JSON configuration given to every labeler");
  cmd->add_option("--gpt", a.gpt_file, "SINC's GPT answers file: the third answer is the truth")
      ->capture_default_str();
  cmd->add_option("--split", a.split, "Which GPT texts: heldout (1 in 5 by hash), train, all, none")
      ->capture_default_str()
      ->check(CLI::IsMember({"heldout", "train", "all", "none"}));
  cmd->add_option("--corpus", a.corpus,
                  "A generated corpus: its texts (known parts) and labelled segments");
  cmd->add_option("--segments", a.segments, "Segments scored for motion-based labelers")
      ->capture_default_str();
  cmd->add_option("--show-errors", a.show_errors, "Print this many disagreements per data set");
  cmd->callback([exit_code] { *exit_code = RunEval(a); });
}

}  // namespace

void AddLabelsCommands(CLI::App& app, int* exit_code) {
  CLI::App* group = app.add_subcommand(
      "labels", "Body-part labels of action texts (SINC): label texts, score labelers");
  group->require_subcommand(1);
  AddLabel(group, exit_code);
  AddEval(group, exit_code);
}

}  // namespace motionpipe::cli
