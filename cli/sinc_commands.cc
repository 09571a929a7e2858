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

}  // namespace

void AddSincCommands(CLI::App& app, int* exit_code) {
  CLI::App* group =
      app.add_subcommand("sinc", "SINC: compose motions by body parts, export synthetic pairs");
  group->require_subcommand(1);
  {  // compose
    auto* cmd = group->add_subcommand(
        "compose", "Compose two motions (BVH, clip or AMASS files) by body parts");
    static std::string a_path, b_path, out, parts_a_text, parts_b_text, text_a, text_b,
        crop_text = "centre", labeler_name = "lexicon";
    static double fps = 30;
    cmd->add_option("first", a_path, "First motion")->required()->check(CLI::ExistingFile);
    cmd->add_option("second", b_path, "Second motion")->required()->check(CLI::ExistingFile);
    cmd->add_option("--out", out, "Output: .bvh (SMPL-22 BVH) or .npz (clip file)")->required();
    cmd->add_option(
        "--parts-a", parts_a_text,
        "Parts of the first action, e.g. 'legs+global'; default: labelled from --text-a");
    cmd->add_option("--parts-b", parts_b_text, "Parts of the second action, e.g. 'right arm'");
    cmd->add_option("--text-a", text_a,
                    "Action text of the first motion (labelled when --parts-a is not given)");
    cmd->add_option("--text-b", text_b, "Action text of the second motion");
    cmd->add_option("--labeler", labeler_name, "Labeler for the texts")->capture_default_str();
    cmd->add_option("--crop", crop_text,
                    "first | centre: which frames of the longer motion are kept")
        ->capture_default_str();
    cmd->add_option("--fps", fps, "Working frame rate")->capture_default_str();
    cmd->callback([exit_code] {
      auto crop = sinc::ParseCropMode(crop_text);
      if (!crop.ok()) return void(*exit_code = Fail(crop.status()));
      auto a = LoadOne(a_path, fps);
      if (!a.ok()) return void(*exit_code = Fail(a.status()));
      auto b = LoadOne(b_path, fps);
      if (!b.ok()) return void(*exit_code = Fail(b.status()));
      PartSet pa = 0, pb = 0;
      for (auto [text, parts_text, parts, which] : {std::tuple{&text_a, &parts_a_text, &pa, "a"},
                                                    std::tuple{&text_b, &parts_b_text, &pb, "b"}}) {
        if (!parts_text->empty()) {
          auto parsed = ParseParts(*parts_text);
          if (!parsed.ok()) return void(*exit_code = Fail(parsed.status()));
          *parts = *parsed;
        } else if (!text->empty()) {
          auto labeler = worker::MakeLabeler(labeler_name, nlohmann::json::object(), nullptr);
          if (!labeler.ok()) return void(*exit_code = Fail(labeler.status()));
          auto labelled = (*labeler)->Label({{*text, nullptr}});
          if (!labelled.ok()) return void(*exit_code = Fail(labelled.status()));
          *parts = labelled->front();
        } else {
          return void(*exit_code = Fail(InvalidArgument(std::string("give --parts-") + which +
                                                        " or --text-" + which)));
        }
      }
      if (!sinc::Compatible(pa, pb)) {
        std::fprintf(stderr,
                     "note: the part sets overlap (%s / %s): the second motion's parts override "
                     "(SINC step 5)\n",
                     PartSetToString(pa).c_str(), PartSetToString(pb).c_str());
      }
      sinc::CompositionPlan plan;
      const Motion composed = sinc::Compose(a->motion, pa, b->motion, pb, *crop, &plan);
      const sinc::CompositionScores scores = sinc::ScoreComposition(composed);
      Status written;
      if (out.size() > 4 && out.compare(out.size() - 4, 4, ".bvh") == 0) {
        written = WriteFileAtomic(out, ExportBvh(composed));
      } else {
        Clip clip;
        clip.id = fs::path(a_path).stem().string() + "+" + fs::path(b_path).stem().string();
        clip.source = "sinc:" + a_path + "+" + b_path;
        clip.motion = composed;
        if (!text_a.empty() && !text_b.empty()) clip.texts = {sinc::EvalPairText(text_a, text_b)};
        written = WriteClips(out, {clip});
      }
      if (!written.ok()) return void(*exit_code = Fail(written));
      std::printf(
          "%s: %lld frames at %.0f fps; A = %s (%s), B = %s (%s)%s; from B: %s%s\n", out.c_str(),
          static_cast<long long>(composed.num_frames()), composed.fps,
          plan.swapped ? b_path.c_str() : a_path.c_str(), PartSetToString(plan.a_parts).c_str(),
          plan.swapped ? a_path.c_str() : b_path.c_str(), PartSetToString(plan.b_parts).c_str(),
          plan.swapped ? " (swapped: B has fewer parts)" : "", PartSetToString(plan.from_b).c_str(),
          plan.root_from_b ? " + translation" : "");
      std::printf(
          "checks: foot skate %.3f, floor penetration %.3f m, largest joint step %.3f m/frame\n",
          scores.skate_ratio, scores.penetration, scores.max_step);
    });
  }
  {  // summary
    auto* cmd = group->add_subcommand(
        "summary", "Print a synth stage's summary (pairs, drops, bytes, memory) and example texts");
    static std::string dir;
    cmd->add_option("dir", dir, "The synth stage directory (with result/ and task-*/)")->required();
    cmd->callback([exit_code] {
      auto text = ReadFile(dir + "/result/summary.json");
      if (!text.ok()) return void(*exit_code = Fail(text.status()));
      const nlohmann::json s = nlohmann::json::parse(*text, nullptr, false);
      if (!s.is_object())
        return void(*exit_code = Fail(DataLoss(dir + "/result/summary.json: not JSON")));
      std::string drops;
      for (const auto& item : s["dropped"].items())
        drops += (drops.empty() ? "" : ", ") + item.key() + " " +
                 std::to_string(item.value().get<int64_t>());
      std::printf(
          "%lld pairs from %lld candidates (%.2f%% kept%s%s%s); recipes %.1f MB, %.1f bytes a "
          "pair; %.0f pairs per task-second\n",
          static_cast<long long>(s.value("pairs", int64_t{0})),
          static_cast<long long>(s.value("candidates", int64_t{0})),
          100.0 * s.value("kept_fraction", 0.0), drops.empty() ? "" : "; dropped: ", drops.c_str(),
          drops.empty() ? "" : "", static_cast<double>(s.value("recipe_bytes", int64_t{0})) / 1e6,
          s.value("bytes_per_pair", 0.0), s.value("pairs_per_task_second", 0.0));
      for (const auto& w : s["workers"]) {
        std::printf(
            "  worker pid %lld: %lld shard(s), resident %.0f MB after its first and %.0f MB after "
            "its last\n",
            static_cast<long long>(w.value("pid", int64_t{0})),
            static_cast<long long>(w.value("shards", int64_t{0})),
            static_cast<double>(w.value("rss_after_first_shard", int64_t{0})) / 1e6,
            static_cast<double>(w.value("rss_after_last_shard", int64_t{0})) / 1e6);
      }
      // A few texts of the first shard.
      auto source = ReadFile(layout::TaskDir(dir) + "/source.json");
      if (!source.ok()) return;
      auto table = sinc::ReadSpans(nlohmann::json::parse(*source).value("spans", std::string()));
      auto shard = sinc::ReadPairs(layout::TaskDir(dir) + "/pairs.npz");
      if (!table.ok() || !shard.ok()) return;
      for (size_t k = 0; k < std::min<size_t>(5, shard->recipes.size()); ++k) {
        const auto& r = shard->recipes[k];
        std::printf("  \"%s\"  (%s + %s)\n", sinc::MaterialiseText(*table, r).c_str(),
                    PartSetToString(r.first_parts).c_str(),
                    PartSetToString(r.second_parts).c_str());
      }
    });
  }
  {  // export
    auto* cmd = group->add_subcommand(
        "export", "Materialise synthetic pairs (recipes) as motions or 135-d features");
    static std::string input, out, spans_override;
    static int64_t limit = -1;
    static bool features = false;
    static int threads = 1;
    cmd->add_option("input", input, "A synth stage directory (task-*/pairs.npz) or one pairs.npz")
        ->required();
    cmd->add_option("--out", out, "Output .npz")->required();
    cmd->add_option("--spans", spans_override,
                    "The spans.npz the recipes index (default: from source.json)");
    cmd->add_option("--limit", limit, "Only the first N pairs");
    cmd->add_flag("--features", features, "Write 135-d TEMOS features instead of motions");
    cmd->add_option("--threads", threads, "Threads")->capture_default_str();
    cmd->callback([exit_code] {
      std::vector<std::string> files;
      if (fs::is_directory(input)) {
        for (const auto& entry : fs::directory_iterator(input)) {
          if (fs::exists(entry.path() / "pairs.npz"))
            files.push_back((entry.path() / "pairs.npz").string());
        }
        std::sort(files.begin(), files.end());
      } else {
        files.push_back(input);
      }
      if (files.empty()) return void(*exit_code = Fail(NotFound(input + ": no pairs.npz")));
      std::string spans_path = spans_override;
      if (spans_path.empty()) {
        auto source = ReadFile((fs::path(files.front()).parent_path() / "source.json").string());
        if (!source.ok())
          return void(*exit_code = Fail(InvalidArgument("give --spans (no source.json beside " +
                                                        files.front() + ")")));
        spans_path = nlohmann::json::parse(*source).value("spans", std::string());
      }
      auto table = sinc::ReadSpans(spans_path);
      if (!table.ok()) return void(*exit_code = Fail(table.status()));
      std::vector<sinc::PairRecipe> recipes;
      sinc::CropMode crop = sinc::CropMode::kFirst;
      for (const std::string& file : files) {
        auto shard = sinc::ReadPairs(file);
        if (!shard.ok()) return void(*exit_code = Fail(shard.status()));
        crop = shard->crop;
        for (const auto& r : shard->recipes) {
          if (r.first < 0 || r.second < 0 || r.first >= table->size() ||
              r.second >= table->size()) {
            return void(*exit_code =
                            Fail(DataLoss(file + ": a recipe indexes span " +
                                          std::to_string(std::max(r.first, r.second)) + " but " +
                                          spans_path + " has " + std::to_string(table->size()))));
          }
          recipes.push_back(r);
        }
      }
      if (limit >= 0 && static_cast<int64_t>(recipes.size()) > limit)
        recipes.resize(static_cast<size_t>(limit));
      const Status s = features ? sinc::ExportPairsAsFeatures(*table, recipes, crop, out, threads)
                                : sinc::ExportPairsAsClips(*table, recipes, crop, out);
      if (!s.ok()) return void(*exit_code = Fail(s));
      std::printf("%s: %zu pairs (%s)\n", out.c_str(), recipes.size(),
                  features ? "135-d features" : "motions");
      for (size_t k = 0; k < std::min<size_t>(3, recipes.size()); ++k)
        std::printf("  %s\n", sinc::MaterialiseText(*table, recipes[k]).c_str());
    });
  }
}

}  // namespace motionpipe::cli
