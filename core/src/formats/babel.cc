#include "motionpipe/formats/babel.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>

#include "motionpipe/base/file.h"

namespace motionpipe {

namespace {

Result<BabelLabel> ParseLabel(const nlohmann::json& node, const std::string& where, bool need_times,
                              double duration) {
  if (!node.is_object()) return DataLoss(where + ": label is not an object");
  BabelLabel label;
  const auto text_field = [&](const char* name, std::string* out) -> Status {
    if (!node.contains(name) || node[name].is_null()) return Status::Ok();
    if (!node[name].is_string()) return DataLoss(where + ": '" + name + "' is not a string");
    *out = node[name].get<std::string>();
    return Status::Ok();
  };
  MP_RETURN_IF_ERROR(text_field("proc_label", &label.proc_label));
  MP_RETURN_IF_ERROR(text_field("raw_label", &label.raw_label));
  if (label.proc_label.empty()) label.proc_label = label.raw_label;
  if (label.proc_label.empty())
    return DataLoss(where + ": label has neither proc_label nor raw_label");
  if (node.contains("act_cat") && node["act_cat"].is_array()) {
    for (const auto& cat : node["act_cat"]) {
      if (cat.is_string()) label.act_cat.push_back(cat.get<std::string>());
    }
  }
  if (need_times) {
    if (!node.contains("start_t") || !node["start_t"].is_number() || !node.contains("end_t") ||
        !node["end_t"].is_number()) {
      return DataLoss(where + ": frame label '" + label.proc_label +
                      "' lacks numeric start_t/end_t");
    }
    label.start_t = node["start_t"].get<double>();
    label.end_t = node["end_t"].get<double>();
    if (!std::isfinite(label.start_t) || !std::isfinite(label.end_t) ||
        std::abs(label.start_t) > 86400 || std::abs(label.end_t) > 86400) {
      return DataLoss(where + ": label '" + label.proc_label +
                      "' has an implausible start_t/end_t");
    }
    if (label.end_t < label.start_t)
      return DataLoss(where + ": label '" + label.proc_label + "' has end_t before start_t");
  } else {
    label.start_t = 0;
    label.end_t = duration;
  }
  return label;
}

}  // namespace

Result<std::vector<BabelSequence>> ParseBabel(const std::string& json_text,
                                              const std::string& origin) {
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(json_text);
  } catch (const nlohmann::json::exception& error) {
    return DataLoss(origin + ": malformed JSON: " + error.what());
  }
  if (!doc.is_object()) return DataLoss(origin + ": expected a JSON object of sequences");
  std::vector<BabelSequence> sequences;
  for (const auto& [key, node] : doc.items()) {
    const std::string where = origin + ": sequence '" + key + "'";
    if (!node.is_object()) return DataLoss(where + ": is not an object");
    BabelSequence seq;
    seq.sid = key;
    if (node.contains("babel_sid") && node["babel_sid"].is_number_integer()) {
      seq.sid = std::to_string(node["babel_sid"].get<int64_t>());
    }
    if (node.contains("feat_p") && node["feat_p"].is_string())
      seq.feat_p = node["feat_p"].get<std::string>();
    if (!node.contains("dur") || !node["dur"].is_number())
      return DataLoss(where + ": missing numeric 'dur'");
    seq.duration = node["dur"].get<double>();
    // A day is far beyond any capture session; larger values are corrupt and would overflow frame
    // counts.
    if (!std::isfinite(seq.duration) || seq.duration < 0 || seq.duration > 86400) {
      return DataLoss(where + ": 'dur' must be between 0 and 86400 seconds");
    }
    const bool has_frame = node.contains("frame_ann") && !node["frame_ann"].is_null();
    const nlohmann::json* ann = nullptr;
    if (has_frame) {
      ann = &node["frame_ann"];
      seq.frame_level = true;
    } else if (node.contains("seq_ann") && !node["seq_ann"].is_null()) {
      ann = &node["seq_ann"];
    } else {
      return DataLoss(where + ": neither frame_ann nor seq_ann");
    }
    if (!ann->is_object() || !ann->contains("labels") || !(*ann)["labels"].is_array()) {
      return DataLoss(where + ": annotation has no 'labels' list");
    }
    for (const auto& label_node : (*ann)["labels"]) {
      MP_ASSIGN_OR_RETURN(BabelLabel label,
                          ParseLabel(label_node, where, seq.frame_level, seq.duration));
      seq.labels.push_back(std::move(label));
    }
    sequences.push_back(std::move(seq));
  }
  return sequences;
}

Result<std::vector<BabelSequence>> ReadBabel(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(path));
  return ParseBabel(text, path);
}

bool IsExcludedBabelLabel(const std::string& label) {
  std::string squashed;
  for (char c : label) {
    if (std::isalnum(static_cast<unsigned char>(c)))
      squashed.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  }
  return squashed == "tpose" || squashed == "apose" || squashed == "transition" ||
         squashed == "transitions";
}

std::vector<ActionSpan> SweepActionSpans(const BabelSequence& sequence,
                                         const BabelSpanOptions& options) {
  struct Event {
    int frame;
    bool start;
    size_t label;
  };
  std::vector<Event> events;
  const int total = static_cast<int>(std::lround(sequence.duration * options.fps));
  for (size_t k = 0; k < sequence.labels.size(); ++k) {
    const BabelLabel& label = sequence.labels[k];
    if (IsExcludedBabelLabel(label.proc_label)) continue;
    const int start =
        std::clamp(static_cast<int>(std::lround(label.start_t * options.fps)), 0, total);
    const int end = std::clamp(static_cast<int>(std::lround(label.end_t * options.fps)), 0, total);
    if (end <= start) continue;
    events.push_back({start, true, k});
    events.push_back({end, false, k});
  }
  std::sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    return a.frame != b.frame ? a.frame < b.frame : (a.start < b.start);  // ends before starts
  });
  std::vector<ActionSpan> spans;
  std::multiset<std::string> active;  // a label may be active twice (overlapping duplicates)
  std::set<std::string> current;      // distinct labels of the span being grown
  int span_start = 0;
  const auto emit = [&](int end) {
    const int length = end - span_start;
    if (!current.empty() && static_cast<int>(current.size()) <= options.max_actions &&
        length >= options.min_frames && length <= options.max_frames) {
      spans.push_back({span_start, end, std::vector<std::string>(current.begin(), current.end())});
    }
  };
  for (size_t k = 0; k < events.size();) {
    const int frame = events[k].frame;
    for (; k < events.size() && events[k].frame == frame; ++k) {
      const std::string& label = sequence.labels[events[k].label].proc_label;
      if (events[k].start) {
        active.insert(label);
      } else {
        active.erase(active.find(label));
      }
    }
    std::set<std::string> next(active.begin(), active.end());
    if (next == current) continue;  // the set did not change: the span goes on
    emit(frame);
    current = std::move(next);
    span_start = frame;
  }
  return spans;
}

}  // namespace motionpipe
