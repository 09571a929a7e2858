#include "post_process.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "generators.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/foot_lock.h"
#include "motionpipe/motion/leg_match.h"
#include "motionpipe/motion/plausibility.h"

namespace motionpipe::cli {

namespace fs = std::filesystem;

std::string PostProcessArgs::Suffix() const {
  std::string s;
  if (!clean_legs.empty()) s += " + clean_legs";
  if (!match_legs.empty()) s += " + match_legs";
  if (foot_lock) s += " + foot_lock";
  return s;
}

void AddPostProcessOptions(CLI::App* cmd, PostProcessArgs* args) {
  cmd->add_option("--clean-legs", args->clean_legs,
                  "Post-process: clean the legs with a leg_cleanup checkpoint (the clean_legs "
                  "stage's; trained on the corpus's motions, it makes real mocap slide more)");
  cmd->add_option("--match-legs", args->match_legs,
                  "Post-process: the legs of the nearest window of these motions (motion "
                  "matching, the match_legs stage's): triplet files or directories holding them "
                  "(e.g. a corpus stage's output; both sides of the --match-split triplets), or "
                  "motion files (clip .npz, AMASS .npz, BVH)");
  cmd->add_option("--match-split", args->match_split, "The triplets' split that --match-legs reads")
      ->capture_default_str();
  cmd->add_flag("--foot-lock", args->foot_lock,
                "Post-process: plant the feet (the foot_lock stage's defaults), after the others");
}

namespace {

bool IsTripletFile(const std::string& path) {
  const std::string name = fs::path(path).filename().string();
  return name.rfind("triplets", 0) == 0 && fs::path(path).extension() == ".npz";
}

// A --match-legs path's triplet files: a stage's directory (its result's triplets, else its
// tasks'), a folder or file of them; empty for a motion file.
Result<std::vector<std::string>> MatchTripletFiles(const std::string& path) {
  std::error_code ec;
  const bool dir = fs::is_directory(path, ec);
  if (!dir && !IsTripletFile(path)) return std::vector<std::string>{};
  std::vector<std::string> files =
      dir ? StageTripletFiles(layout::StageOutputDirs(path)) : std::vector{path};
  if (files.empty()) return NotFound(path + ": --match-legs: holds no triplet files");
  return files;
}

Status NoMatchMotions(const PostProcessArgs& args) {
  return NotFound("--match-legs: no motions (no triplets of split '" + args.match_split +
                  "' and no motion files)");
}

// The --clean-legs checkpoint, checked to be a leg_cleanup one.
Result<std::string> CleanupCheckpoint(const PostProcessArgs& args) {
  MP_ASSIGN_OR_RETURN(const std::string checkpoint, worker::ResolveCheckpoint(args.clean_legs));
  MP_ASSIGN_OR_RETURN(const std::string name, worker::CheckpointModelName(checkpoint));
  if (name != "leg_cleanup")
    return InvalidArgument("--clean-legs: " + checkpoint + " is a " + name +
                           " checkpoint, not a leg_cleanup one");
  return checkpoint;
}

// The match_legs database at `fps` from the arguments' paths.
Status FillDatabase(const PostProcessArgs& args, double fps, LegDatabase* database) {
  int64_t motions = 0;
  for (const std::string& path : args.match_legs) {
    MP_ASSIGN_OR_RETURN(const std::vector<std::string> files, MatchTripletFiles(path));
    if (!files.empty()) {
      MP_ASSIGN_OR_RETURN(
          const int64_t triplets,
          AddTripletSides(
              files, args.match_split, 0,
              [&](const Motion& motion) { return ToModelRate(motion, fps); }, database));
      motions += 2 * triplets;
      continue;
    }
    MP_ASSIGN_OR_RETURN(const std::vector<Clip> clips, LoadMotionFile(path, fps));
    for (const Clip& clip : clips) {
      MP_RETURN_IF_ERROR(database->Add(ToModelRate(clip.motion, fps), path + ", " + clip.id));
      ++motions;
    }
  }
  if (motions == 0) return NoMatchMotions(args);
  std::printf("match_legs: database of %lld motions, %lld frames at %.0f fps\n",
              static_cast<long long>(motions), static_cast<long long>(database->frames()), fps);
  return Status::Ok();
}

void PrintPlausibility(const char* what, const Motion& motion) {
  const PlausibilityReport r = EvaluateMotionPlausibility(Skeleton::Smpl22(), motion);
  std::printf(
      "%s: foot skate %.3f of contact frames (GMD's ratio %.3f), floating %.2f, jerk %.0f "
      "m/s^3\n",
      what, r.foot_skate_ratio, r.skating_ratio_gmd, r.float_ratio, r.jerk_mean);
}

}  // namespace

Status CheckPostProcesses(const PostProcessArgs& args) {
  if (!args.clean_legs.empty()) MP_RETURN_IF_ERROR(CleanupCheckpoint(args).status());
  int64_t motions = 0;
  for (const std::string& path : args.match_legs) {
    MP_ASSIGN_OR_RETURN(const std::vector<std::string> files, MatchTripletFiles(path));
    for (const std::string& file : files) {
      MP_ASSIGN_OR_RETURN(const TripletColumns columns,
                          ReadTripletColumns(file, {0, -1, /*motions=*/false, false}));
      motions += std::count(columns.splits.begin(), columns.splits.end(), args.match_split);
    }
    if (files.empty()) {
      MP_ASSIGN_OR_RETURN(const std::vector<Clip> clips, LoadMotionFile(path, 30));
      motions += static_cast<int64_t>(clips.size());
    }
  }
  if (!args.match_legs.empty() && motions == 0) return NoMatchMotions(args);
  return Status::Ok();
}

Result<Motion> ApplyPostProcesses(const PostProcessArgs& args, const worker::PluginHost& host,
                                  const Motion& raw) {
  Motion motion = raw;
  if (!args.clean_legs.empty()) {
    MP_ASSIGN_OR_RETURN(const std::string checkpoint, CleanupCheckpoint(args));
    MP_ASSIGN_OR_RETURN(auto cleanup, worker::LoadGenerator(host, checkpoint));
    plugin::GenerateRequest request;
    request.source = &motion;
    MP_ASSIGN_OR_RETURN(motion, cleanup->Generate(request));
    std::printf("clean_legs: the legs cleaned by %s\n", checkpoint.c_str());
  }
  if (!args.match_legs.empty()) {
    LegDatabase database(Skeleton::Smpl22(), LegMatchOptions{});
    MP_RETURN_IF_ERROR(FillDatabase(args, motion.fps, &database));
    LegMatchReport report;
    MP_ASSIGN_OR_RETURN(motion, database.Match(motion, &report));
    std::printf("match_legs: %lld window(s), cost %.2f per compared frame, legs changed %.1f deg\n",
                static_cast<long long>(report.windows), report.MeanCost(), report.MeanDegrees());
  }
  if (args.foot_lock) {
    FootLockReport report;
    motion = LockFeet(Skeleton::Smpl22(), motion, FootLockOptions{}, &report);
    std::printf(
        "foot_lock: %lld foot-joint frames held in %lld runs (moved %.3f m on average), "
        "%lld ankle frames out of reach, pelvis lowered up to %.3f m\n",
        static_cast<long long>(report.held), static_cast<long long>(report.runs),
        report.MeanShift(), static_cast<long long>(report.unreached), report.max_lowered);
  }
  PrintPlausibility(args.any() ? "plausibility, raw" : "plausibility", raw);
  if (args.any()) PrintPlausibility(("plausibility, " + args.Suffix().substr(3)).c_str(), motion);
  return motion;
}

}  // namespace motionpipe::cli
