// `motionpipe sinc ...`: compose two motions by body parts (SINC sec. 3.1) and export synthetic
// pairs.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "commands.h"
#include "labelers.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/formats/bvh.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/sinc/composition.h"
#include "motionpipe/sinc/synth.h"

namespace motionpipe::cli {

namespace {

namespace fs = std::filesystem;

// "global,left leg,right leg" or "legs+global" -> parts; "" -> 0.
Result<PartSet> ParseParts(const std::string& text) {
  PartSet parts = 0;
  std::string item;
  std::string normalised = text;
  for (char& c : normalised) {
    if (c == '+' || c == ';') c = ',';
    if (c == '_' || c == '-') c = ' ';
  }
  std::istringstream in(normalised);
  while (std::getline(in, item, ',')) {
    while (!item.empty() && item.front() == ' ') item.erase(item.begin());
    while (!item.empty() && item.back() == ' ') item.pop_back();
    if (item.empty()) continue;
    if (item == "arms") {
      parts |= static_cast<PartSet>(PartBit(BodyPart::kLeftArm) | PartBit(BodyPart::kRightArm));
    } else if (item == "legs") {
      parts |= static_cast<PartSet>(PartBit(BodyPart::kLeftLeg) | PartBit(BodyPart::kRightLeg));
    } else {
      bool found = false;
      for (int p = 0; p < kNumBodyParts; ++p) {
        if (BodyPartNames()[static_cast<size_t>(p)] == item) {
          parts |= static_cast<PartSet>(1u << p);
          found = true;
        }
      }
      if (!found)
        return InvalidArgument(
            "unknown body part '" + item +
            "' (global, torso, left arm, right arm, left leg, right leg, arms, legs)");
    }
  }
  return parts;
}

Result<Clip> LoadOne(const std::string& path, double fps) {
  MP_ASSIGN_OR_RETURN(std::vector<Clip> clips, LoadMotionFile(path, fps));
  if (clips.empty()) return DataLoss(path + ": no motion");
  return std::move(clips.front());
}

// ---- sinc compose ------------------------------------------------------------------------------
struct ComposeArgs {
  std::string a_path, b_path, out, parts_a_text, parts_b_text, text_a, text_b;
  std::string crop_text = "centre", labeler_name = "lexicon";
  double fps = 30;
};

// The parts of one action: --parts-X as given, else its --text-X labelled. `which` is "a" or "b".
// A part list that does not parse, or neither option, is a usage error (exit 2).
Result<PartSet> PartsOf(const std::string& parts_text, const std::string& text,
                        const std::string& labeler_name, const std::string& which) {
  if (!parts_text.empty()) return ParseParts(parts_text);
  if (text.empty()) return InvalidArgument("give --parts-" + which + " or --text-" + which);
  auto labeler = worker::MakeLabeler(labeler_name, nlohmann::json::object(), nullptr);
  if (!labeler.ok()) return labeler.status();
  MP_ASSIGN_OR_RETURN(const std::vector<PartSet> labelled, (*labeler)->Label({{text, nullptr}}));
  return labelled.front();
}

Status WriteComposition(const ComposeArgs& a, const Motion& composed) {
  if (a.out.size() > 4 && a.out.compare(a.out.size() - 4, 4, ".bvh") == 0)
    return WriteFileAtomic(a.out, ExportBvh(composed));
  Clip clip;
  clip.id = fs::path(a.a_path).stem().string() + "+" + fs::path(a.b_path).stem().string();
  clip.source = "sinc:" + a.a_path + "+" + a.b_path;
  clip.motion = composed;
  if (!a.text_a.empty() && !a.text_b.empty()) clip.texts = {sinc::EvalPairText(a.text_a, a.text_b)};
  return WriteClips(a.out, {clip});
}

int RunCompose(const ComposeArgs& a) {
  auto crop = sinc::ParseCropMode(a.crop_text);
  if (!crop.ok()) return Usage(crop.status().message());
  auto first = LoadOne(a.a_path, a.fps);
  if (!first.ok()) return Fail(first.status());
  auto second = LoadOne(a.b_path, a.fps);
  if (!second.ok()) return Fail(second.status());
  auto pa = PartsOf(a.parts_a_text, a.text_a, a.labeler_name, "a");
  if (!pa.ok())
    return pa.status().code() == StatusCode::kInvalidArgument ? Usage(pa.status().message())
                                                              : Fail(pa.status());
  auto pb = PartsOf(a.parts_b_text, a.text_b, a.labeler_name, "b");
  if (!pb.ok())
    return pb.status().code() == StatusCode::kInvalidArgument ? Usage(pb.status().message())
                                                              : Fail(pb.status());
  if (!sinc::Compatible(*pa, *pb)) {
    std::fprintf(stderr,
                 "note: the part sets overlap (%s / %s): the second motion's parts override "
                 "(SINC step 5)\n",
                 PartSetToString(*pa).c_str(), PartSetToString(*pb).c_str());
  }
  sinc::CompositionPlan plan;
  const Motion composed = sinc::Compose(first->motion, *pa, second->motion, *pb, *crop, &plan);
  const sinc::CompositionScores scores = sinc::ScoreComposition(composed);
  if (Status s = WriteComposition(a, composed); !s.ok()) return Fail(s);
  std::printf(
      "%s: %lld frames at %.0f fps; A = %s (%s), B = %s (%s)%s; from B: %s%s\n", a.out.c_str(),
      static_cast<long long>(composed.num_frames()), composed.fps,
      plan.swapped ? a.b_path.c_str() : a.a_path.c_str(), PartSetToString(plan.a_parts).c_str(),
      plan.swapped ? a.a_path.c_str() : a.b_path.c_str(), PartSetToString(plan.b_parts).c_str(),
      plan.swapped ? " (swapped: B has fewer parts)" : "", PartSetToString(plan.from_b).c_str(),
      plan.root_from_b ? " + translation" : "");
  std::printf(
      "checks: foot skate %.3f, floor penetration %.3f m, largest joint step %.3f m/frame\n",
      scores.skate_ratio, scores.penetration, scores.max_step);
  return kExitOk;
}

void AddCompose(CLI::App* group, int* exit_code) {
  auto* cmd = group->add_subcommand("compose",
                                    "Compose two motions (BVH, clip or AMASS files) by body parts");
  static ComposeArgs a;
  cmd->add_option("first", a.a_path, "First motion")->required()->check(CLI::ExistingFile);
  cmd->add_option("second", a.b_path, "Second motion")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a.out, "Output: .bvh (SMPL-22 BVH) or .npz (clip file)")->required();
  cmd->add_option("--parts-a", a.parts_a_text,
                  "Parts of the first action, e.g. 'legs+global'; default: labelled from --text-a");
  cmd->add_option("--parts-b", a.parts_b_text, "Parts of the second action, e.g. 'right arm'");
  cmd->add_option("--text-a", a.text_a,
                  "Action text of the first motion (labelled when --parts-a is not given)");
  cmd->add_option("--text-b", a.text_b, "Action text of the second motion");
  cmd->add_option("--labeler", a.labeler_name, "Labeler for the texts")->capture_default_str();
  cmd->add_option("--crop", a.crop_text,
                  "first | centre: which frames of the longer motion are kept")
      ->capture_default_str();
  cmd->add_option("--fps", a.fps, "Working frame rate")->capture_default_str();
  cmd->callback([exit_code] { *exit_code = RunCompose(a); });
}

// ---- sinc summary ------------------------------------------------------------------------------
// A few texts of the synth stage's first shard; nothing when its files cannot be read.
void PrintExampleTexts(const std::string& dir) {
  auto source = ReadFile(layout::TaskDir(dir) + "/source.json");
  if (!source.ok()) return;
  const nlohmann::json parsed = nlohmann::json::parse(*source, nullptr, false);
  if (!parsed.is_object()) return;
  auto table = sinc::ReadSpans(parsed.value("spans", std::string()));
  auto shard = sinc::ReadPairs(layout::TaskDir(dir) + "/pairs.npz");
  if (!table.ok() || !shard.ok()) return;
  for (size_t k = 0; k < std::min<size_t>(5, shard->recipes.size()); ++k) {
    const auto& r = shard->recipes[k];
    std::printf("  \"%s\"  (%s + %s)\n", sinc::MaterialiseText(*table, r).c_str(),
                PartSetToString(r.first_parts).c_str(), PartSetToString(r.second_parts).c_str());
  }
}

int RunSummary(const std::string& dir) {
  const std::string path = dir + "/result/summary.json";
  auto text = ReadFile(path);
  if (!text.ok()) return Fail(text.status());
  const nlohmann::json s = nlohmann::json::parse(*text, nullptr, false);
  if (!s.is_object()) return Fail(DataLoss(path + ": not JSON"));
  std::string drops;
  for (const auto& item : s["dropped"].items())
    drops += (drops.empty() ? "" : ", ") + item.key() + " " +
             std::to_string(item.value().get<int64_t>());
  std::printf(
      "%lld pairs from %lld candidates (%.2f%% kept%s%s); recipes %.1f MB, %.1f bytes a pair; "
      "%.0f pairs per task-second\n",
      static_cast<long long>(s.value("pairs", int64_t{0})),
      static_cast<long long>(s.value("candidates", int64_t{0})),
      100.0 * s.value("kept_fraction", 0.0), drops.empty() ? "" : "; dropped: ", drops.c_str(),
      static_cast<double>(s.value("recipe_bytes", int64_t{0})) / 1e6,
      s.value("bytes_per_pair", 0.0), s.value("pairs_per_task_second", 0.0));
  for (const auto& w : s["workers"]) {
    std::printf(
        "  worker pid %lld: %lld shard(s), resident %.0f MB after its first and %.0f MB after its "
        "last\n",
        static_cast<long long>(w.value("pid", int64_t{0})),
        static_cast<long long>(w.value("shards", int64_t{0})),
        static_cast<double>(w.value("rss_after_first_shard", int64_t{0})) / 1e6,
        static_cast<double>(w.value("rss_after_last_shard", int64_t{0})) / 1e6);
  }
  PrintExampleTexts(dir);
  return kExitOk;
}

void AddSummary(CLI::App* group, int* exit_code) {
  auto* cmd = group->add_subcommand(
      "summary", "Print a synth stage's summary (pairs, drops, bytes, memory) and example texts");
  static std::string dir;
  cmd->add_option("dir", dir, "The synth stage directory (with result/ and task-*/)")->required();
  cmd->callback([exit_code] { *exit_code = RunSummary(dir); });
}

// ---- sinc export -------------------------------------------------------------------------------
struct ExportArgs {
  std::string input, out, spans_override;
  int64_t limit = -1;
  bool features = false;
  int threads = 1;
};

// The pairs files of a synth stage directory (task-*/pairs.npz, sorted), or `input` itself.
std::vector<std::string> PairFilesIn(const std::string& input) {
  if (!fs::is_directory(input)) return {input};
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(input)) {
    if (fs::exists(entry.path() / "pairs.npz"))
      files.push_back((entry.path() / "pairs.npz").string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Every recipe of `files`, each checked against the span table it indexes; `crop` is the last
// file's crop mode.
Result<std::vector<sinc::PairRecipe>> ReadRecipes(const std::vector<std::string>& files,
                                                  const sinc::SpanTable& table,
                                                  const std::string& spans_path,
                                                  sinc::CropMode* crop) {
  std::vector<sinc::PairRecipe> recipes;
  for (const std::string& file : files) {
    MP_ASSIGN_OR_RETURN(const auto shard, sinc::ReadPairs(file));
    *crop = shard.crop;
    for (const auto& r : shard.recipes) {
      if (r.first < 0 || r.second < 0 || r.first >= table.size() || r.second >= table.size()) {
        return DataLoss(file + ": a recipe indexes span " +
                        std::to_string(std::max(r.first, r.second)) + " but " + spans_path +
                        " has " + std::to_string(table.size()));
      }
      recipes.push_back(r);
    }
  }
  return recipes;
}

int RunExport(const ExportArgs& a) {
  const std::vector<std::string> files = PairFilesIn(a.input);
  if (files.empty()) return Fail(NotFound(a.input + ": no pairs.npz"));
  std::string spans_path = a.spans_override;
  if (spans_path.empty()) {
    const std::string source_path =
        (fs::path(files.front()).parent_path() / "source.json").string();
    auto source = ReadFile(source_path);
    if (!source.ok()) return Usage("give --spans (no source.json beside " + files.front() + ")");
    const nlohmann::json parsed = nlohmann::json::parse(*source, nullptr, false);
    if (!parsed.is_object()) return Fail(DataLoss(source_path + ": not JSON"));
    spans_path = parsed.value("spans", std::string());
  }
  auto table = sinc::ReadSpans(spans_path);
  if (!table.ok()) return Fail(table.status());
  sinc::CropMode crop = sinc::CropMode::kFirst;
  auto recipes = ReadRecipes(files, *table, spans_path, &crop);
  if (!recipes.ok()) return Fail(recipes.status());
  if (a.limit >= 0 && static_cast<int64_t>(recipes->size()) > a.limit)
    recipes->resize(static_cast<size_t>(a.limit));
  const Status s = a.features
                       ? sinc::ExportPairsAsFeatures(*table, *recipes, crop, a.out, a.threads)
                       : sinc::ExportPairsAsClips(*table, *recipes, crop, a.out);
  if (!s.ok()) return Fail(s);
  std::printf("%s: %zu pairs (%s)\n", a.out.c_str(), recipes->size(),
              a.features ? "135-d features" : "motions");
  for (size_t k = 0; k < std::min<size_t>(3, recipes->size()); ++k)
    std::printf("  %s\n", sinc::MaterialiseText(*table, (*recipes)[k]).c_str());
  return kExitOk;
}

void AddExport(CLI::App* group, int* exit_code) {
  auto* cmd = group->add_subcommand(
      "export", "Materialise synthetic pairs (recipes) as motions or 135-d features");
  static ExportArgs a;
  cmd->add_option("input", a.input, "A synth stage directory (task-*/pairs.npz) or one pairs.npz")
      ->required();
  cmd->add_option("--out", a.out, "Output .npz")->required();
  cmd->add_option("--spans", a.spans_override,
                  "The spans.npz the recipes index (default: from source.json)");
  cmd->add_option("--limit", a.limit, "Only the first N pairs");
  cmd->add_flag("--features", a.features, "Write 135-d TEMOS features instead of motions");
  cmd->add_option("--threads", a.threads, "Threads")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  cmd->callback([exit_code] { *exit_code = RunExport(a); });
}

}  // namespace

void AddSincCommands(CLI::App& app, int* exit_code) {
  CLI::App* group =
      app.add_subcommand("sinc", "SINC: compose motions by body parts, export synthetic pairs");
  group->require_subcommand(1);
  AddCompose(group, exit_code);
  AddSummary(group, exit_code);
  AddExport(group, exit_code);
}

}  // namespace motionpipe::cli
