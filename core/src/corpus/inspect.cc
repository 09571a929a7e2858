#include "motionpipe/corpus/inspect.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <vector>

#include "motionpipe/base/file.h"
#include "motionpipe/formats/babel.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/plausibility.h"

namespace motionpipe::corpus {

namespace {
std::vector<std::string> ShardFiles(const std::string& dir, const std::string& prefix) {
  std::vector<std::string> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) == 0 && entry.path().extension() == ".npz")
      files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}
}  // namespace

Result<CorpusReport> InspectCorpus(const std::string& dir) {
  CorpusReport report;
  MP_ASSIGN_OR_RETURN(const std::string manifest_text, ReadFile(dir + "/manifest.json"));
  nlohmann::json manifest;
  try {
    manifest = nlohmann::json::parse(manifest_text);
    report.seed = manifest.at("seed").get<uint64_t>();
    report.fps = manifest.at("fps").get<double>();
    report.rejected = manifest.at("rejected").get<int64_t>();
  } catch (const nlohmann::json::exception& error) {
    return DataLoss(dir + "/manifest.json: " + error.what());
  }
  if (manifest.value("format", "") != "motionpipe.corpus/1")
    return DataLoss(dir + "/manifest.json: not a motionpipe corpus");

  const Skeleton& skeleton = Skeleton::Smpl22();
  std::vector<double> skates, seconds;
  std::set<std::string> labels, captions;
  double jerk_sum = 0;
  for (const std::string& file : ShardFiles(dir + "/clips", "clips-")) {
    MP_ASSIGN_OR_RETURN(const std::vector<Clip> clips, ReadClips(file));
    for (const Clip& clip : clips) {
      ++report.clips;
      report.frames += clip.motion.num_frames();
      seconds.push_back(clip.motion.duration_seconds());
      if (!clip.texts.empty()) captions.insert(clip.texts.front());
      for (const Segment& seg : clip.segments) {
        ++report.segments;
        labels.insert(seg.text);
        if (!seg.action.empty()) ++report.actions[seg.action];
        for (int p = 0; p < kNumBodyParts; ++p)
          report.part_segments[static_cast<size_t>(p)] += (seg.parts >> p) & 1;
      }
      const PlausibilityReport r = EvaluateMotionPlausibility(skeleton, clip.motion);
      skates.push_back(r.foot_skate_ratio);
      report.penetration_max = std::max(report.penetration_max, r.penetration_max);
      report.bone_error_max = std::max(report.bone_error_max, r.bone_length_error);
      report.joint_limit_violations += r.joint_limit_violations;
      jerk_sum += r.jerk_mean;
    }
  }
  if (report.clips == 0) return DataLoss(dir + "/clips: no clip shards");
  std::sort(skates.begin(), skates.end());
  report.skate_max = skates.back();
  report.skate_p95 = skates[skates.size() * 95 / 100];
  for (double s : skates) report.skate_mean += s / static_cast<double>(skates.size());
  report.jerk_mean = jerk_sum / static_cast<double>(report.clips);
  report.min_seconds = *std::min_element(seconds.begin(), seconds.end());
  report.max_seconds = *std::max_element(seconds.begin(), seconds.end());
  for (double s : seconds) report.mean_seconds += s / static_cast<double>(seconds.size());
  report.distinct_labels = static_cast<int64_t>(labels.size());
  report.distinct_captions = static_cast<int64_t>(captions.size());

  for (const char* split : {"train", "val", "test"}) {
    MP_ASSIGN_OR_RETURN(const auto sequences, ReadBabel(dir + "/babel/" + split + ".json"));
    report.split_clips[split] = static_cast<int64_t>(sequences.size());
    for (const BabelSequence& seq : sequences) {
      ++report.babel_sequences;
      for (const ActionSpan& span : SweepActionSpans(seq, {report.fps, 15, 600, 4})) {
        if (span.labels.size() == 1)
          ++report.babel_singles;
        else if (span.labels.size() == 2)
          ++report.babel_pairs;
        else
          ++report.babel_multi;
      }
    }
  }

  double source_seconds = 0, target_seconds = 0, edited = 0;
  int64_t with_range = 0;
  for (const std::string& file : ShardFiles(dir + "/motionfix", "triplets-")) {
    MP_ASSIGN_OR_RETURN(const std::vector<Triplet> triplets, ReadTriplets(file));
    for (const Triplet& t : triplets) {
      ++report.triplets;
      ++report.split_triplets[t.split];
      if (!t.edit_kind.empty()) ++report.edit_kinds[t.edit_kind];
      source_seconds += t.source.duration_seconds();
      target_seconds += t.target.duration_seconds();
      if (t.edit_start >= 0 && t.edit_end > t.edit_start) {
        edited += static_cast<double>(t.edit_end - t.edit_start) /
                  static_cast<double>(t.source.num_frames());
        ++with_range;
      }
    }
  }
  if (report.triplets > 0) {
    report.mean_source_seconds = source_seconds / static_cast<double>(report.triplets);
    report.mean_target_seconds = target_seconds / static_cast<double>(report.triplets);
  }
  if (with_range > 0) report.mean_edited_fraction = edited / static_cast<double>(with_range);
  return report;
}

std::string FormatCorpusReport(const CorpusReport& r) {
  std::string out;
  char line[512];
  const auto add = [&](const char* format, auto... args) {
    std::snprintf(line, sizeof(line), format, args...);
    out += line;
  };
  add("corpus: seed %llu, %.0f fps\n", static_cast<unsigned long long>(r.seed), r.fps);
  add("clips: %lld (train %lld, val %lld, test %lld), %lld frames, %.1f min; %.1f-%.1f s, mean "
      "%.1f s\n",
      static_cast<long long>(r.clips),
      static_cast<long long>(r.split_clips.count("train") ? r.split_clips.at("train") : 0),
      static_cast<long long>(r.split_clips.count("val") ? r.split_clips.at("val") : 0),
      static_cast<long long>(r.split_clips.count("test") ? r.split_clips.at("test") : 0),
      static_cast<long long>(r.frames), static_cast<double>(r.frames) / r.fps / 60.0, r.min_seconds,
      r.max_seconds, r.mean_seconds);
  add("segments: %lld labelled actions, %lld distinct labels, %lld distinct captions, %zu actions "
      "used\n",
      static_cast<long long>(r.segments), static_cast<long long>(r.distinct_labels),
      static_cast<long long>(r.distinct_captions), r.actions.size());
  add("BABEL sweep: %lld sequences -> %lld single-action spans, %lld simultaneous pairs, %lld with "
      "3-4 actions\n",
      static_cast<long long>(r.babel_sequences), static_cast<long long>(r.babel_singles),
      static_cast<long long>(r.babel_pairs), static_cast<long long>(r.babel_multi));
  out += "parts (segments using each):";
  static const char* kParts[] = {"global",    "torso",    "left arm",
                                 "right arm", "left leg", "right leg"};
  for (int p = 0; p < 6; ++p)
    add(" %s %lld%s", kParts[p], static_cast<long long>(r.part_segments[static_cast<size_t>(p)]),
        p < 5 ? "," : "\n");
  out += "actions:";
  int column = 0;
  std::vector<std::pair<int64_t, std::string>> sorted;
  for (const auto& [name, count] : r.actions) sorted.push_back({count, name});
  std::sort(sorted.rbegin(), sorted.rend());
  for (const auto& [count, name] : sorted) {
    add("%s%s %lld", column % 6 == 0 ? "\n  " : ", ", name.c_str(), static_cast<long long>(count));
    ++column;
  }
  out += "\n";
  add("triplets: %lld (train %lld, val %lld, test %lld); source %.1f s, target %.1f s on average; "
      "edited range %.0f%% of the source\n",
      static_cast<long long>(r.triplets),
      static_cast<long long>(r.split_triplets.count("train") ? r.split_triplets.at("train") : 0),
      static_cast<long long>(r.split_triplets.count("val") ? r.split_triplets.at("val") : 0),
      static_cast<long long>(r.split_triplets.count("test") ? r.split_triplets.at("test") : 0),
      r.mean_source_seconds, r.mean_target_seconds, 100 * r.mean_edited_fraction);
  out += "edits:";
  for (const auto& [kind, count] : r.edit_kinds)
    add(" %s %lld", kind.c_str(), static_cast<long long>(count));
  out += "\n";
  add("plausibility: foot skate ratio mean %.4f, p95 %.4f, max %.4f; floor penetration max %.4f m; "
      "bone-length error max %.1e m;\n"
      "              joint-limit violations %lld; mean jerk %.0f m/s^3; %lld scripts resampled by "
      "the gate\n",
      r.skate_mean, r.skate_p95, r.skate_max, r.penetration_max, r.bone_error_max,
      static_cast<long long>(r.joint_limit_violations), r.jerk_mean,
      static_cast<long long>(r.rejected));
  return out;
}

}  // namespace motionpipe::corpus
