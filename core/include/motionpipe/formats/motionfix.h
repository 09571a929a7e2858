// Editing triplets (source motion, target motion, edit text) in our MotionFix-converted layout.
// MotionFix ships as a joblib pickle; tools/motionfix_convert.py turns it into this npz once:
//
//   format          <U ()          "motionpipe.triplets/1"
//   ids, texts      <U (N,)        triplet id and edit instruction
//   splits          <U (N,)        "train" / "val" / "test"
//   fps             f8 (N,)
//   source_offsets  i8 (N+1,)      triplet i's source frames are source_*[offsets[i]:offsets[i+1]]
//   source_poses    f4 (F, 22, 3)  axis-angle, z-up (MotionFix `rots`)
//   source_trans    f4 (F, 3)
//   source_joints   f4 (F, 22, 3)  optional (MotionFix `joint_positions`)
//   target_*                      the same for the target motions
//   edit_start/end  i4 (N,)        ground-truth edited source frames [start, end); -1 when unknown
//   edit_kind       <U (N,)        optional: the kind of edit (procedural corpus ground truth)
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/npz.h"
#include "motionpipe/motion/leg_match.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe {

inline constexpr char kTripletsFormat[] = "motionpipe.triplets/1";

struct Triplet {
  std::string id;
  std::string text;
  std::string split;
  Motion source;
  Motion target;
  std::vector<float> source_joints;  // [T, 22, 3] or empty
  std::vector<float> target_joints;
  int32_t edit_start = -1;
  int32_t edit_end = -1;
  std::string edit_kind;  // empty when unknown
};

Npz TripletsToNpz(const std::vector<Triplet>& triplets);
// Every shape and offset is checked; a triplet whose motions are invalid fails with its id.
Result<std::vector<Triplet>> TripletsFromNpz(const Npz& npz, const std::string& origin);
// Uncompressed by default (numpy's savez): ReadTripletColumns then maps the file and uses the
// arrays in place, several times faster than inflating them.
Status WriteTriplets(const std::string& path, const std::vector<Triplet>& triplets,
                     bool compress = false);
Result<std::vector<Triplet>> ReadTriplets(const std::string& path);

// The triplet files a directory holds, sorted: DIR/motionfix/triplets*.npz (what the corpus and
// dataset stages write), else DIR/triplets*.npz; empty when it holds neither. The one rule by which
// the filter, the editors' data and the evaluation stages find triplets in a directory.
std::vector<std::string> TripletFilesIn(const std::string& dir);

// The triplet files of stages' output directories (each stage's as layout::StageOutputDirs lists
// them, stages one after another): a stage's result directory's when it holds any (a corpus's
// result holds every triplet, its tasks the same files as shards), else each of its directories'
// (TripletFilesIn). Directories are of one stage when they share a parent. Sorted, no repeats.
std::vector<std::string> StageTripletFiles(const std::vector<std::string>& dirs);

}  // namespace motionpipe

namespace motionpipe {

// The columns of a triplets file for bulk consumers such as the similarity filter. The file's
// structure is checked (format, shapes, monotone offsets); the content of each triplet (NaN, empty
// or one-frame motions, joint counts that differ between source and target) is not, so that the
// consumer can drop bad triplets one by one with a reason instead of refusing the whole file.
struct TripletColumns {
  // One side's arrays; the pointers stay valid as long as any copy of the columns lives (the
  // arrays are shared, not copied: a float32 file is read without converting or copying its data).
  struct Side {
    std::vector<int64_t> offsets;  // rows + 1, from 0
    int joints = 0;                // rotations per frame in `poses` (22; more for SMPL-H/X bodies)
    const float* poses = nullptr;  // [F, joints, 3] axis-angle
    const float* trans = nullptr;  // [F, 3]
    int position_joints = 0;       // 0 when the file has no joint positions (or they were not read)
    const float* positions = nullptr;  // [F, position_joints, 3]
    std::vector<std::shared_ptr<const void>> storage;
  };
  std::string origin;
  int64_t first_row = 0;  // row of the file that is row 0 here
  int64_t rows = 0;
  std::vector<std::string> ids, texts, splits, kinds;  // kinds: empty strings when unknown
  std::vector<double> fps;
  std::vector<int32_t> edit_start, edit_end;  // -1 when unknown
  Side source, target;
};

struct TripletColumnOptions {
  int64_t row_begin = 0;
  int64_t row_end = -1;   // -1: to the end
  bool motions = true;    // poses and trans
  bool positions = true;  // the stored joint positions, when present
};

// Reads rows [row_begin, row_end) of a triplets file; arrays that are not asked for are never
// inflated. Errors name the file and the array.
Result<TripletColumns> ReadTripletColumns(const std::string& path,
                                          const TripletColumnOptions& options = {});

// The number of triplets in a file (reads only its ids).
Result<int64_t> CountTriplets(const std::string& path);

// Row `row`'s source or target motion (poses and trans at the file's rate) of columns read with
// motions.
Motion SideMotion(const TripletColumns& c, int64_t row, bool source);

// Calls `visit` with both sides (source, then target; at the file's rate) of each triplet of
// `split` in the triplets file `path`, in row order, with an origin naming the file, the triplet
// and the side; at most `limit` triplets (0: all). Returns how many triplets it visited; the
// first error of reading the file or of `visit` ends it.
Result<int64_t> VisitTripletSides(
    const std::string& path, const std::string& split, int64_t limit,
    const std::function<Status(const Motion& motion, const std::string& origin)>& visit);

// Both sides of the `split` triplets of `files` (at most `limit` triplets in all, 0: all), each as
// `convert` gives it (e.g. at the model's rate), added to `database` in the files' and rows' order,
// the database as Add one side at a time would fill it; the sides' rows are prepared (converted,
// features and leg places) several files at once (OpenMP, a file to a thread). Returns the
// triplets added; the first error in that order ends it, naming the file, triplet and side.
Result<int64_t> AddTripletSides(const std::vector<std::string>& files, const std::string& split,
                                int64_t limit, const std::function<Motion(const Motion&)>& convert,
                                LegDatabase* database);

}  // namespace motionpipe
