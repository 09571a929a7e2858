// The dataset-filtering job of SimMotionEdit (paper sec. 3.2.1 and 4.2): similarity curves,
// MotionSNR and classes for every triplet of a set, sharded so that workers can split it.
//
// One shard writes into its directory:
//   similarity.npz  format "motionpipe.similarity/1"; per kept triplet: ids, files, rows, splits,
//                   snr f8; per kept frame (offsets i8 (N+1,)): similarity f4 (eq. 6, in [0, 1]),
//                   classes u1 (eq. 10; absent for regression), combined f4 (eq. 5, smoothed),
//                   raw_rot f4 and raw_loc f4 (eq. 4); options (JSON text) and edit ranges
//   dropped.json    [{id, file, row, reason, detail, snr?}] for every dropped triplet
//   stats.json      counts for the summary (kept, dropped by reason, SNR values, class frames,
//                   agreement with known edited frames)
// The summary (reduce) writes summary.json, summary.png (SNR histogram, class frames, example
// curves, precision/recall at the class boundaries), dropped.json (all shards) and index.json (the
// shards).
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/similarity/similarity.h"

namespace motionpipe::similarity {

inline constexpr char kSimilarityFormat[] = "motionpipe.similarity/1";

struct TripletFile {
  std::string path;
  int64_t count = 0;
};

// Every triplets file named by `inputs`: files as given, directories searched for
// motionfix/triplets-*.npz, then triplets-*.npz, then *.npz. Sorted within each directory, and
// counted (reading only the ids). NotFound/InvalidArgument name the input.
Result<std::vector<TripletFile>> ResolveTripletFiles(const std::vector<std::string>& inputs);

struct ShardSlice {
  std::string path;
  int64_t row_begin = 0, row_end = 0;
};

// The rows shard `index` of `shards` filters. With at least as many files as shards, each shard
// takes whole consecutive files (balanced by triplet count), so no file is decompressed twice;
// otherwise the concatenated rows are cut into equal ranges.
std::vector<ShardSlice> PlanShard(const std::vector<TripletFile>& files, int shards, int index);

struct ShardReport {
  int64_t triplets = 0, kept = 0;
  double seconds = 0;
};

// Filters the slices with `threads` OpenMP threads and writes the shard files into `out_dir`
// (created). Output bytes do not depend on the thread count. Bad triplets are dropped with a
// reason; a file that cannot be read at all is an error naming it.
Result<ShardReport> FilterShard(const std::vector<ShardSlice>& slices,
                                const SimilarityOptions& options, int threads,
                                const std::string& out_dir);

// Merges shard directories (in order) into summary.json, summary.png, dropped.json and index.json
// in `out_dir`; returns the summary.
Result<nlohmann::json> SummarizeFilter(const std::vector<std::string>& shard_dirs,
                                       const std::string& out_dir);

// A few human-readable lines about a summary (for the CLI and logs).
std::string FormatFilterSummary(const nlohmann::json& summary);

// A shard's similarity.npz, read back (for trainers and tests).
struct SimilarityTable {
  SimilarityOptions options;
  std::vector<std::string> ids, files, splits;
  std::vector<int64_t> rows, offsets;
  std::vector<double> snr;
  std::vector<float> similarity, combined, raw_rot, raw_loc;
  std::vector<uint8_t> classes;  // empty in regression mode
  std::vector<int32_t> edit_start, edit_end;
};
Result<SimilarityTable> ReadSimilarity(const std::string& path);

}  // namespace motionpipe::similarity
