// `motionpipe data ...`: import, export, inspect and round-trip motion files.
#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "commands.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/corpus/corpus.h"
#include "motionpipe/corpus/inspect.h"
#include "motionpipe/features/motionfix207.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/formats/amass.h"
#include "motionpipe/formats/bvh.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/motion/compare.h"
#include "motionpipe/similarity/filter.h"

namespace motionpipe::cli {

namespace {

int Fail(const Status& status) {
  std::cerr << "error: " << status.message() << "\n";
  return kExitFailure;
}

std::string Stem(const std::string& path) { return std::filesystem::path(path).stem().string(); }

// Per-frame lowest foot joint height, median over the clip (metres): ~0 when feet touch the floor.
double MedianLowestFoot(const Skeleton& skeleton, const std::vector<float>& joints,
                        int64_t frames) {
  std::vector<double> lowest;
  for (int64_t frame = 0; frame < frames; ++frame) {
    double low = 1e30;
    for (int j : {skeleton.left_foot_joints()[0], skeleton.left_foot_joints()[1],
                  skeleton.right_foot_joints()[0], skeleton.right_foot_joints()[1]}) {
      low = std::min(
          low, static_cast<double>(joints[static_cast<size_t>((frame * kNumJoints + j) * 3 + 2)]));
    }
    lowest.push_back(low);
  }
  std::nth_element(lowest.begin(), lowest.begin() + static_cast<std::ptrdiff_t>(lowest.size() / 2),
                   lowest.end());
  return lowest[lowest.size() / 2];
}

struct RoundTrip {
  double feature207 = 0, feature135 = 0, bvh = 0;  // max joint position error, metres
  double median_lowest_foot = 0;
};

Result<RoundTrip> RoundTripClip(const Clip& clip, const std::string& out_dir) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  const Motion& motion = clip.motion;
  RoundTrip rt;
  const FeatureMatrix f207 = EncodeMotionFix207(skeleton, motion);
  rt.feature207 =
      CompareMotions(skeleton, motion, DecodeMotionFix207(f207, AnchorOf(motion), motion.fps))
          .max_joint;
  const FeatureMatrix f135 = EncodeTemos135(motion);
  rt.feature135 =
      CompareMotions(skeleton, motion, DecodeTemos135(f135, AnchorOf(motion), motion.fps))
          .max_joint;
  const std::string bvh_text = ExportBvh(motion);
  const std::string bvh_path = out_dir + "/" + clip.id + ".smpl22.bvh";
  MP_RETURN_IF_ERROR(WriteFileAtomic(bvh_path, bvh_text));
  BvhImportOptions options;
  options.fps = 0;
  options.place_on_floor = false;
  MP_ASSIGN_OR_RETURN(const Clip back, ImportBvhFile(bvh_path, options));
  rt.bvh = CompareMotions(skeleton, motion, back.motion).max_joint;
  rt.median_lowest_foot =
      MedianLowestFoot(skeleton, ComputeJoints(skeleton, motion), motion.num_frames());
  return rt;
}

}  // namespace

void AddDataCommands(CLI::App& app, int* exit_code) {
  CLI::App* data = app.add_subcommand("data", "Import, export, inspect and convert motion data");
  data->require_subcommand(1);

  {  // import-bvh
    auto* cmd = data->add_subcommand("import-bvh",
                                     "Retarget a BVH file onto SMPL-22 and write a clip file");
    static std::string input, output, map;
    static double fps = 30;
    static bool keep_height = false;
    cmd->add_option("file", input, "BVH file")->required()->check(CLI::ExistingFile);
    cmd->add_option("--out", output, "Output clip file (.npz)")->required();
    cmd->add_option("--fps", fps, "Resample to this frame rate (0 keeps the file's)")
        ->capture_default_str();
    cmd->add_option("--map", map, "Joint map file: 'smpl_joint: source_joint' lines")
        ->check(CLI::ExistingFile);
    cmd->add_flag("--keep-height", keep_height, "Do not move the feet onto the floor");
    cmd->callback([exit_code] {
      BvhImportOptions options;
      options.fps = fps;
      options.map_path = map;
      options.place_on_floor = !keep_height;
      auto clip = ImportBvhFile(input, options);
      if (!clip.ok()) return void(*exit_code = Fail(clip.status()));
      clip->id = Stem(input);
      clip->joints = ComputeJoints(Skeleton::Smpl22(), clip->motion);
      if (Status s = WriteClips(output, {*clip}); !s.ok()) return void(*exit_code = Fail(s));
      std::printf("%s: %lld frames at %.1f fps (%s) -> %s\n", input.c_str(),
                  static_cast<long long>(clip->motion.num_frames()), clip->motion.fps,
                  clip->source.c_str(), output.c_str());
    });
  }
  {  // export-bvh
    auto* cmd = data->add_subcommand("export-bvh",
                                     "Write a clip (or AMASS npz, or BVH) as an SMPL-22 BVH file");
    static std::string input, output, clip_id;
    static double units = 100;
    cmd->add_option("file", input, "Clip file, AMASS npz or BVH")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--out", output, "Output BVH file")->required();
    cmd->add_option("--clip", clip_id, "Clip id when the file holds several (default: the first)");
    cmd->add_option("--units-per-metre", units, "BVH units per metre (100 = centimetres)")
        ->capture_default_str();
    cmd->callback([exit_code] {
      auto clips = LoadMotionFile(input);
      if (!clips.ok()) return void(*exit_code = Fail(clips.status()));
      const auto it = clip_id.empty() ? clips->begin()
                                      : std::find_if(clips->begin(), clips->end(),
                                                     [](const Clip& c) { return c.id == clip_id; });
      if (it == clips->end())
        return void(*exit_code = Fail(NotFound(input + ": no clip '" + clip_id + "'")));
      if (Status s = ExportBvhFile(output, it->motion, {units}); !s.ok())
        return void(*exit_code = Fail(s));
      std::printf("%s: clip '%s', %lld frames -> %s\n", input.c_str(), it->id.c_str(),
                  static_cast<long long>(it->motion.num_frames()), output.c_str());
    });
  }
  {  // import-amass
    auto* cmd =
        data->add_subcommand("import-amass", "Convert an AMASS npz (SMPL-H/SMPL-X) to a clip file");
    static std::string input, output;
    static double fps = 30;
    cmd->add_option("file", input, "AMASS npz")->required()->check(CLI::ExistingFile);
    cmd->add_option("--out", output, "Output clip file (.npz)")->required();
    cmd->add_option("--fps", fps, "Resample by index selection (0 keeps the file's rate)")
        ->capture_default_str();
    cmd->callback([exit_code] {
      auto clip = ReadAmassNpz(input, fps);
      if (!clip.ok()) return void(*exit_code = Fail(clip.status()));
      clip->id = Stem(input);
      if (Status s = WriteClips(output, {*clip}); !s.ok()) return void(*exit_code = Fail(s));
      std::printf("%s: %lld frames at %.1f fps -> %s\n", input.c_str(),
                  static_cast<long long>(clip->motion.num_frames()), clip->motion.fps,
                  output.c_str());
    });
  }
  {  // info
    auto* cmd = data->add_subcommand("info", "Describe motion files (clip files, AMASS npz, BVH)");
    static std::vector<std::string> inputs;
    cmd->add_option("files", inputs, "Files")->required()->check(CLI::ExistingFile);
    cmd->callback([exit_code] {
      for (const std::string& input : inputs) {
        auto clips = LoadMotionFile(input);
        if (!clips.ok()) {
          *exit_code = Fail(clips.status());
          continue;
        }
        std::printf("%s: %zu clip(s)\n", input.c_str(), clips->size());
        for (const Clip& clip : *clips) {
          std::printf("  %-24s %6lld frames  %6.1f fps  %7.2f s  %zu text(s)  %zu segment(s)  %s\n",
                      clip.id.c_str(), static_cast<long long>(clip.motion.num_frames()),
                      clip.motion.fps, clip.motion.duration_seconds(), clip.texts.size(),
                      clip.segments.size(), clip.source.c_str());
        }
      }
    });
  }
  {  // synth-corpus
    auto* cmd = data->add_subcommand("synth-corpus",
                                     "Generate the procedural motion corpus (AMASS npz + BABEL "
                                     "JSON + MotionFix-style triplets)");
    static corpus::CorpusOptions options;
    static int64_t triplets = -1;
    static bool no_amass = false, no_joints = false;
    cmd->add_option("--out", options.out_dir, "Output directory")->required();
    cmd->add_option("--seed", options.seed, "Random seed (same seed, same bytes)")
        ->capture_default_str();
    cmd->add_option("--clips", options.clips, "Number of clips")
        ->capture_default_str()
        ->check(CLI::PositiveNumber);
    cmd->add_option("--triplets", triplets,
                    "Number of editing triplets (default: as many as clips)");
    cmd->add_option("--fps", options.fps, "Frame rate")
        ->capture_default_str()
        ->check(CLI::PositiveNumber);
    cmd->add_option("--threads", options.threads, "OpenMP threads (0 = all cores)")
        ->capture_default_str();
    cmd->add_option("--shard-size", options.shard_size, "Clips or triplets per shard file")
        ->capture_default_str();
    cmd->add_option("--min-seconds", options.script.min_seconds, "Shortest clip")
        ->capture_default_str();
    cmd->add_option("--max-seconds", options.script.max_seconds, "Longest clip")
        ->capture_default_str();
    cmd->add_flag("--no-amass", no_amass, "Skip the per-clip AMASS-style npz files");
    cmd->add_flag("--no-triplet-joints", no_joints,
                  "Do not store FK joint positions with the triplets");
    cmd->callback([exit_code] {
      options.triplets = triplets;
      options.write_amass = !no_amass;
      options.triplet_joints = !no_joints;
      auto summary = corpus::GenerateCorpus(options);
      if (!summary.ok()) return void(*exit_code = Fail(summary.status()));
      std::printf(
          "%s: %lld clips (%lld frames) + %lld triplets in %.1f s (%lld scripts resampled by the "
          "plausibility gate)\n",
          options.out_dir.c_str(), static_cast<long long>(summary->clips),
          static_cast<long long>(summary->frames), static_cast<long long>(summary->triplets),
          summary->seconds, static_cast<long long>(summary->rejected));
    });
  }
  {  // inspect
    auto* cmd =
        data->add_subcommand("inspect", "Summarise a generated corpus (through the real loaders)");
    static std::string dir;
    cmd->add_option("dir", dir, "Corpus directory")->required()->check(CLI::ExistingDirectory);
    cmd->callback([exit_code] {
      auto report = corpus::InspectCorpus(dir);
      if (!report.ok()) return void(*exit_code = Fail(report.status()));
      std::fputs(corpus::FormatCorpusReport(*report).c_str(), stdout);
    });
  }
  {  // filter
    auto* cmd = data->add_subcommand("filter",
                                     "Similarity curves, MotionSNR and classes of editing triplets "
                                     "(SimMotionEdit's filter), in this process");
    static std::vector<std::string> inputs;
    static std::string out_dir;
    static std::string preset = "paper";
    static std::vector<std::string> sets;
    static int threads = 0;
    cmd->add_option("inputs", inputs,
                    "Triplets files (.npz) or directories (a corpus, converted MotionFix)")
        ->required();
    cmd->add_option("--out", out_dir, "Output directory: task-00000/ (curves) and the summary")
        ->required();
    cmd->add_option("--preset", preset,
                    "paper (kappa 5) or reference (the authors' code: kappa 10)")
        ->capture_default_str();
    cmd->add_option(
        "--set", sets,
        "Override a constant, key=value (window, smooth, w_rot, w_loc, kappa, snr_threshold, "
        "min_frames, classes, locations)");
    cmd->add_option("--threads", threads, "OpenMP threads (0 = all cores)")->capture_default_str();
    cmd->callback([exit_code] {
      nlohmann::json config = {{"preset", preset}};
      for (const std::string& set : sets) {
        const size_t eq = set.find('=');
        if (eq == std::string::npos)
          return void(*exit_code = Fail(InvalidArgument("--set " + set + ": expected key=value")));
        const std::string value = set.substr(eq + 1);
        const nlohmann::json parsed = nlohmann::json::parse(value, nullptr, false);
        config[set.substr(0, eq)] = parsed.is_discarded() ? nlohmann::json(value) : parsed;
      }
      auto options = similarity::OptionsFromJson(config, "--preset/--set");
      if (!options.ok()) return void(*exit_code = Fail(options.status()));
      auto files = similarity::ResolveTripletFiles(inputs);
      if (!files.ok()) return void(*exit_code = Fail(files.status()));
      const int n = threads > 0 ? threads : omp_get_max_threads();
      const std::string shard_dir = layout::TaskDir(out_dir);
      auto report =
          similarity::FilterShard(similarity::PlanShard(*files, 1, 0), *options, n, shard_dir);
      if (!report.ok()) return void(*exit_code = Fail(report.status()));
      auto summary = similarity::SummarizeFilter({shard_dir}, out_dir);
      if (!summary.ok()) return void(*exit_code = Fail(summary.status()));
      std::fputs(similarity::FormatFilterSummary(*summary).c_str(), stdout);
      std::printf(
          "%.2f s with %d threads (%.0f triplets/s); curves in %s/similarity.npz, summary in "
          "%s/summary.{json,png}\n",
          report->seconds, n,
          static_cast<double>(report->triplets) / std::max(report->seconds, 1e-9),
          shard_dir.c_str(), out_dir.c_str());
    });
  }
  {  // filter-summary
    auto* cmd = data->add_subcommand(
        "filter-summary", "Print the summary of a filter result directory (summary.json)");
    static std::string dir;
    cmd->add_option("dir", dir, "The filter stage's result directory (or `data filter --out`)")
        ->required();
    cmd->callback([exit_code] {
      auto text = ReadFile(dir + "/summary.json");
      if (!text.ok()) return void(*exit_code = Fail(text.status()));
      const nlohmann::json summary = nlohmann::json::parse(*text, nullptr, false);
      if (summary.is_discarded())
        return void(*exit_code = Fail(DataLoss(dir + "/summary.json: not JSON")));
      try {
        std::fputs(similarity::FormatFilterSummary(summary).c_str(), stdout);
      } catch (const nlohmann::json::exception& e) {
        return void(*exit_code = Fail(
                        DataLoss(dir + "/summary.json: unexpected content (" + e.what() + ")")));
      }
    });
  }
  {  // roundtrip
    auto* cmd = data->add_subcommand("roundtrip",
                                     "Import motions, round-trip them through both feature "
                                     "encodings and BVH export, print a summary");
    static std::vector<std::string> inputs;
    static std::string out_dir = "out/roundtrip";
    static double fps = 30;
    cmd->add_option("files", inputs, "BVH files, clip files or AMASS npz")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--out", out_dir, "Directory for the imported clips and exported BVH files")
        ->capture_default_str();
    cmd->add_option("--fps", fps, "Working frame rate")->capture_default_str();
    cmd->callback([exit_code] {
      if (Status s = MakeDirs(out_dir); !s.ok()) return void(*exit_code = Fail(s));
      std::printf("%-14s %7s %5s %7s | %-28s | %9s\n", "clip", "frames", "fps", "seconds",
                  "round-trip max joint err (m)", "feet (m)");
      std::printf("%-14s %7s %5s %7s | %8s %8s %10s | %9s\n", "", "", "", "", "207-d", "135-d",
                  "BVH", "median");
      double worst = 0;
      for (const std::string& input : inputs) {
        auto clips = LoadMotionFile(input, fps);
        if (!clips.ok()) {
          *exit_code = Fail(clips.status());
          continue;
        }
        for (Clip& clip : *clips) {
          if (clip.id.empty() || clips->size() == 1) clip.id = Stem(input);
          clip.joints = ComputeJoints(Skeleton::Smpl22(), clip.motion);
          if (Status s = WriteClips(out_dir + "/" + clip.id + ".npz", {clip}); !s.ok()) {
            *exit_code = Fail(s);
            continue;
          }
          auto rt = RoundTripClip(clip, out_dir);
          if (!rt.ok()) {
            *exit_code = Fail(rt.status());
            continue;
          }
          worst = std::max({worst, rt->feature207, rt->feature135, rt->bvh});
          std::printf("%-14s %7lld %5.0f %7.2f | %8.1e %8.1e %10.1e | %9.3f\n", clip.id.c_str(),
                      static_cast<long long>(clip.motion.num_frames()), clip.motion.fps,
                      clip.motion.duration_seconds(), rt->feature207, rt->feature135, rt->bvh,
                      rt->median_lowest_foot);
        }
      }
      std::printf("worst round-trip error: %.2e m; clips and BVH files in %s\n", worst,
                  out_dir.c_str());
    });
  }
}

}  // namespace motionpipe::cli
