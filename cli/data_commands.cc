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

// ---- data import-bvh ---------------------------------------------------------------------------
struct ImportBvhArgs {
  std::string input, output, map;
  double fps = 30;
  bool keep_height = false;
};

int RunImportBvh(const ImportBvhArgs& a) {
  BvhImportOptions options;
  options.fps = a.fps;
  options.map_path = a.map;
  options.place_on_floor = !a.keep_height;
  auto clip = ImportBvhFile(a.input, options);
  if (!clip.ok()) return Fail(clip.status());
  clip->id = Stem(a.input);
  clip->joints = ComputeJoints(Skeleton::Smpl22(), clip->motion);
  if (Status s = WriteClips(a.output, {*clip}); !s.ok()) return Fail(s);
  std::printf("%s: %lld frames at %.1f fps (%s) -> %s\n", a.input.c_str(),
              static_cast<long long>(clip->motion.num_frames()), clip->motion.fps,
              clip->source.c_str(), a.output.c_str());
  return kExitOk;
}

void AddImportBvh(CLI::App* data, int* exit_code) {
  auto* cmd =
      data->add_subcommand("import-bvh", "Retarget a BVH file onto SMPL-22 and write a clip file");
  static ImportBvhArgs a;
  cmd->add_option("file", a.input, "BVH file")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a.output, "Output clip file (.npz)")->required();
  cmd->add_option("--fps", a.fps, "Resample to this frame rate (0 keeps the file's)")
      ->capture_default_str();
  cmd->add_option("--map", a.map, "Joint map file: 'smpl_joint: source_joint' lines")
      ->check(CLI::ExistingFile);
  cmd->add_flag("--keep-height", a.keep_height, "Do not move the feet onto the floor");
  cmd->callback([exit_code] { *exit_code = RunImportBvh(a); });
}

// ---- data export-bvh ---------------------------------------------------------------------------
struct ExportBvhArgs {
  std::string input, output, clip_id;
  double units = 100;
};

int RunExportBvh(const ExportBvhArgs& a) {
  auto clips = LoadMotionFile(a.input);
  if (!clips.ok()) return Fail(clips.status());
  auto found = FindClip(*clips, a.clip_id, a.input);
  if (!found.ok()) return Fail(found.status());
  const Clip* it = *found;
  if (Status s = ExportBvhFile(a.output, it->motion, {a.units}); !s.ok()) return Fail(s);
  std::printf("%s: clip '%s', %lld frames -> %s\n", a.input.c_str(), it->id.c_str(),
              static_cast<long long>(it->motion.num_frames()), a.output.c_str());
  return kExitOk;
}

void AddExportBvh(CLI::App* data, int* exit_code) {
  auto* cmd = data->add_subcommand("export-bvh",
                                   "Write a clip (or AMASS npz, or BVH) as an SMPL-22 BVH file");
  static ExportBvhArgs a;
  cmd->add_option("file", a.input, "Clip file, AMASS npz or BVH")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", a.output, "Output BVH file")->required();
  cmd->add_option("--clip", a.clip_id, "Clip id when the file holds several (default: the first)");
  cmd->add_option("--units-per-metre", a.units, "BVH units per metre (100 = centimetres)")
      ->capture_default_str();
  cmd->callback([exit_code] { *exit_code = RunExportBvh(a); });
}

// ---- data import-amass -------------------------------------------------------------------------
struct ImportAmassArgs {
  std::string input, output;
  double fps = 30;
};

int RunImportAmass(const ImportAmassArgs& a) {
  auto clip = ReadAmassNpz(a.input, a.fps);
  if (!clip.ok()) return Fail(clip.status());
  clip->id = Stem(a.input);
  if (Status s = WriteClips(a.output, {*clip}); !s.ok()) return Fail(s);
  std::printf("%s: %lld frames at %.1f fps -> %s\n", a.input.c_str(),
              static_cast<long long>(clip->motion.num_frames()), clip->motion.fps,
              a.output.c_str());
  return kExitOk;
}

void AddImportAmass(CLI::App* data, int* exit_code) {
  auto* cmd =
      data->add_subcommand("import-amass", "Convert an AMASS npz (SMPL-H/SMPL-X) to a clip file");
  static ImportAmassArgs a;
  cmd->add_option("file", a.input, "AMASS npz")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a.output, "Output clip file (.npz)")->required();
  cmd->add_option("--fps", a.fps, "Resample by index selection (0 keeps the file's rate)")
      ->capture_default_str();
  cmd->callback([exit_code] { *exit_code = RunImportAmass(a); });
}

// ---- data info ---------------------------------------------------------------------------------
struct InfoArgs {
  std::vector<std::string> inputs;
};

int RunInfo(const InfoArgs& a) {
  int code = kExitOk;
  for (const std::string& input : a.inputs) {
    auto clips = LoadMotionFile(input);
    if (!clips.ok()) {
      code = Fail(clips.status());
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
  return code;
}

void AddInfo(CLI::App* data, int* exit_code) {
  auto* cmd = data->add_subcommand("info", "Describe motion files (clip files, AMASS npz, BVH)");
  static InfoArgs a;
  cmd->add_option("files", a.inputs, "Files")->required()->check(CLI::ExistingFile);
  cmd->callback([exit_code] { *exit_code = RunInfo(a); });
}

// ---- data synth-corpus -------------------------------------------------------------------------
struct SynthCorpusArgs {
  corpus::CorpusOptions options;
  int64_t triplets = -1;
  bool no_amass = false, no_joints = false;
};

int RunSynthCorpus(const SynthCorpusArgs& a) {
  corpus::CorpusOptions options = a.options;
  options.triplets = a.triplets;
  options.write_amass = !a.no_amass;
  options.triplet_joints = !a.no_joints;
  auto summary = corpus::GenerateCorpus(options);
  if (!summary.ok()) return Fail(summary.status());
  std::printf(
      "%s: %lld clips (%lld frames) + %lld triplets in %.1f s (%lld scripts resampled by the "
      "plausibility gate)\n",
      options.out_dir.c_str(), static_cast<long long>(summary->clips),
      static_cast<long long>(summary->frames), static_cast<long long>(summary->triplets),
      summary->seconds, static_cast<long long>(summary->rejected));
  return kExitOk;
}

void AddSynthCorpus(CLI::App* data, int* exit_code) {
  auto* cmd = data->add_subcommand("synth-corpus",
                                   "Generate the procedural motion corpus (AMASS npz + BABEL "
                                   "JSON + MotionFix-style triplets)");
  static SynthCorpusArgs a;
  corpus::CorpusOptions& options = a.options;
  cmd->add_option("--out", options.out_dir, "Output directory")->required();
  cmd->add_option("--seed", options.seed, "Random seed (same seed, same bytes)")
      ->capture_default_str();
  cmd->add_option("--clips", options.clips, "Number of clips")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--triplets", a.triplets,
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
  cmd->add_option("--manner-words", options.manner_words,
                  "Share of clip texts that state the action's manner when clearly off normal "
                  "(tempo, repetitions, size); the motions stay the same")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_flag("--no-amass", a.no_amass, "Skip the per-clip AMASS-style npz files");
  cmd->add_flag("--no-triplet-joints", a.no_joints,
                "Do not store FK joint positions with the triplets");
  cmd->callback([exit_code] { *exit_code = RunSynthCorpus(a); });
}

// ---- data inspect ------------------------------------------------------------------------------
struct InspectArgs {
  std::string dir;
};

int RunInspect(const InspectArgs& a) {
  auto report = corpus::InspectCorpus(a.dir);
  if (!report.ok()) return Fail(report.status());
  std::fputs(corpus::FormatCorpusReport(*report).c_str(), stdout);
  return kExitOk;
}

void AddInspect(CLI::App* data, int* exit_code) {
  auto* cmd =
      data->add_subcommand("inspect", "Summarize a generated corpus (through the real loaders)");
  static InspectArgs a;
  cmd->add_option("dir", a.dir, "Corpus directory")->required()->check(CLI::ExistingDirectory);
  cmd->callback([exit_code] { *exit_code = RunInspect(a); });
}

// ---- data filter -------------------------------------------------------------------------------
struct FilterArgs {
  std::vector<std::string> inputs;
  std::string out_dir;
  std::string preset = "paper";
  std::vector<std::string> sets;  // key=value overrides of the filter's constants
  int threads = 0;
};

int RunFilter(const FilterArgs& a) {
  nlohmann::json config = {{"preset", a.preset}};
  for (const std::string& set : a.sets) {
    const size_t eq = set.find('=');
    if (eq == std::string::npos) return Usage("--set " + set + ": expected key=value");
    const std::string value = set.substr(eq + 1);
    const nlohmann::json parsed = nlohmann::json::parse(value, nullptr, false);
    config[set.substr(0, eq)] = parsed.is_discarded() ? nlohmann::json(value) : parsed;
  }
  auto options = similarity::OptionsFromJson(config, "--preset/--set");
  if (!options.ok()) return Fail(options.status());
  auto files = similarity::ResolveTripletFiles(a.inputs);
  if (!files.ok()) return Fail(files.status());
  const int n = a.threads > 0 ? a.threads : omp_get_max_threads();
  const std::string shard_dir = layout::TaskDir(a.out_dir);
  auto report =
      similarity::FilterShard(similarity::PlanShard(*files, 1, 0), *options, n, shard_dir);
  if (!report.ok()) return Fail(report.status());
  auto summary = similarity::SummarizeFilter({shard_dir}, a.out_dir);
  if (!summary.ok()) return Fail(summary.status());
  std::fputs(similarity::FormatFilterSummary(*summary).c_str(), stdout);
  std::printf(
      "%.2f s with %d threads (%.0f triplets/s); curves in %s/similarity.npz, summary in "
      "%s/summary.{json,png}\n",
      report->seconds, n, static_cast<double>(report->triplets) / std::max(report->seconds, 1e-9),
      shard_dir.c_str(), a.out_dir.c_str());
  return kExitOk;
}

void AddFilter(CLI::App* data, int* exit_code) {
  auto* cmd = data->add_subcommand("filter",
                                   "Similarity curves, MotionSNR and classes of editing triplets "
                                   "(SimMotionEdit's filter), in this process");
  static FilterArgs a;
  cmd->add_option("inputs", a.inputs,
                  "Triplets files (.npz) or directories (a corpus, converted MotionFix)")
      ->required();
  cmd->add_option("--out", a.out_dir, "Output directory: task-00000/ (curves) and the summary")
      ->required();
  cmd->add_option("--preset", a.preset,
                  "paper (kappa 5) or reference (the authors' code: kappa 10)")
      ->capture_default_str();
  cmd->add_option(
      "--set", a.sets,
      "Override a constant, key=value (window, smooth, w_rot, w_loc, kappa, snr_threshold, "
      "min_frames, classes, locations)");
  cmd->add_option("--threads", a.threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->callback([exit_code] { *exit_code = RunFilter(a); });
}

// ---- data filter-summary -----------------------------------------------------------------------
struct FilterSummaryArgs {
  std::string dir;
};

int RunFilterSummary(const FilterSummaryArgs& a) {
  const std::string path = a.dir + "/summary.json";
  auto text = ReadFile(path);
  if (!text.ok()) return Fail(text.status());
  const nlohmann::json summary = nlohmann::json::parse(*text, nullptr, false);
  if (summary.is_discarded()) return Fail(DataLoss(path + ": not JSON"));
  try {
    std::fputs(similarity::FormatFilterSummary(summary).c_str(), stdout);
  } catch (const nlohmann::json::exception& e) {
    return Fail(DataLoss(path + ": unexpected content (" + e.what() + ")"));
  }
  return kExitOk;
}

void AddFilterSummary(CLI::App* data, int* exit_code) {
  auto* cmd = data->add_subcommand("filter-summary",
                                   "Print the summary of a filter result directory (summary.json)");
  static FilterSummaryArgs a;
  cmd->add_option("dir", a.dir, "The filter stage's result directory (or `data filter --out`)")
      ->required();
  cmd->callback([exit_code] { *exit_code = RunFilterSummary(a); });
}

// ---- data roundtrip ----------------------------------------------------------------------------
struct RoundTripArgs {
  std::vector<std::string> inputs;
  std::string out_dir = "out/roundtrip";
  double fps = 30;
};

int RunRoundTrip(const RoundTripArgs& a) {
  if (Status s = MakeDirs(a.out_dir); !s.ok()) return Fail(s);
  std::printf("%-14s %7s %5s %7s | %-28s | %9s\n", "clip", "frames", "fps", "seconds",
              "round-trip max joint err (m)", "feet (m)");
  std::printf("%-14s %7s %5s %7s | %8s %8s %10s | %9s\n", "", "", "", "", "207-d", "135-d", "BVH",
              "median");
  int code = kExitOk;
  double worst = 0;
  for (const std::string& input : a.inputs) {
    auto clips = LoadMotionFile(input, a.fps);
    if (!clips.ok()) {
      code = Fail(clips.status());
      continue;
    }
    for (Clip& clip : *clips) {
      if (clip.id.empty() || clips->size() == 1) clip.id = Stem(input);
      clip.joints = ComputeJoints(Skeleton::Smpl22(), clip.motion);
      if (Status s = WriteClips(a.out_dir + "/" + clip.id + ".npz", {clip}); !s.ok()) {
        code = Fail(s);
        continue;
      }
      auto rt = RoundTripClip(clip, a.out_dir);
      if (!rt.ok()) {
        code = Fail(rt.status());
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
              a.out_dir.c_str());
  return code;
}

void AddRoundTrip(CLI::App* data, int* exit_code) {
  auto* cmd = data->add_subcommand("roundtrip",
                                   "Import motions, round-trip them through both feature "
                                   "encodings and BVH export, print a summary");
  static RoundTripArgs a;
  cmd->add_option("files", a.inputs, "BVH files, clip files or AMASS npz")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", a.out_dir, "Directory for the imported clips and exported BVH files")
      ->capture_default_str();
  cmd->add_option("--fps", a.fps, "Working frame rate")->capture_default_str();
  cmd->callback([exit_code] { *exit_code = RunRoundTrip(a); });
}

}  // namespace

// Each command is an args struct, a run function returning the exit code, and an Add function
// that declares its options (CLI11 writes the parsed values into the static args).
void AddDataCommands(CLI::App& app, int* exit_code) {
  CLI::App* data = app.add_subcommand("data", "Import, export, inspect and convert motion data");
  data->require_subcommand(1);
  AddImportBvh(data, exit_code);
  AddExportBvh(data, exit_code);
  AddImportAmass(data, exit_code);
  AddInfo(data, exit_code);
  AddSynthCorpus(data, exit_code);
  AddInspect(data, exit_code);
  AddFilter(data, exit_code);
  AddFilterSummary(data, exit_code);
  AddRoundTrip(data, exit_code);
}

}  // namespace motionpipe::cli
