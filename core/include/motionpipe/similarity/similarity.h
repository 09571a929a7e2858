// SimMotionEdit's motion similarity (paper sec. 3.2.1, REFERENCE 3.1): per source frame, how close
// the edited (target) motion stays to the source, from which the auxiliary task's classes come.
//
//   eq. (4)  S_i^Rr = -min_j d_r(x^i, m^j), j in [max(c - W, 0), min(c + W, T_m)), c = floor(i T_m
//   / T_x),
//            d = mean absolute difference; rotation branch on the 6D body pose (joints 1..21),
//            location branch S^Rl on joint positions without translation (FK with the pelvis at 0)
//            each branch then smoothed by a moving average (zero padded, numpy's 'same')
//   eq. (5)  S^R = w1 S^Rr + w2 S^Rl
//   eq. (6)  S^N = (S^R - min S^R) / (max S^R - min S^R)
//   eq. (9)  MotionSNR = mean of the kappa largest distances (-S^R) / mean of the kappa smallest
//   eq. (10) class = min(K - 1, floor(K S^N)): K equal bins of [0, 1]
//
// A triplet is kept when both motions have at least min_frames frames and MotionSNR >= threshold.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/motionfix.h"

namespace motionpipe::similarity {

// Where the location branch's joint positions come from.
enum class LocationSource {
  kAuto,               // stored positions minus translation when the file has them, otherwise FK
  kStored,             // the file's joint positions (MotionFix `joint_positions`) minus translation
  kForwardKinematics,  // FK of the poses on the SMPL-22 template skeleton, pelvis at the origin
};

struct SimilarityOptions {
  int window = 15;             // W, eq. (4)
  int smooth = 10;             // moving-average length (1 = none)
  double w_rot = 1.0;          // w1, eq. (5)
  double w_loc = 1.0;          // w2, eq. (5)
  int kappa = 5;               // eq. (7)-(8); the reference code uses 10
  double snr_threshold = 2.0;  // MotionSNR below this drops the pair
  int min_frames = 20;         // both motions at least this long
  int classes = 3;             // K, eq. (10); 0 = regression targets (the normalised curve only)
  LocationSource locations = LocationSource::kAuto;
};

// Named presets: "paper" (every default above) and "reference" (the authors' code: kappa = 10).
Result<SimilarityOptions> SimilarityPreset(const std::string& name);
// Checks ranges; the message names `origin` and the key.
Status ValidateOptions(const SimilarityOptions& options, const std::string& origin);
// From a config object: optional "preset", then any of the keys window, smooth, w_rot, w_loc,
// kappa, snr_threshold, min_frames, classes, locations ("auto" | "stored" | "fk"). Unknown keys are
// errors unless listed in `ignore`.
Result<SimilarityOptions> OptionsFromJson(const nlohmann::json& config, const std::string& origin,
                                          const std::vector<std::string>& ignore = {});
nlohmann::json OptionsToJson(const SimilarityOptions& options);
const char* LocationSourceName(LocationSource source);

// Per-frame branch vectors, padded with zeros to whole SIMD blocks: the rotation branch (6D of
// joints 1..21, the first two rows of each matrix; entry k of every joint together, [21 k, 21 k +
// 21)) in [0, 126), then the location branch (22 joints x 3, the pelvis at the origin) in
// [kLocOffset, kLocOffset + 66).
inline constexpr int kRotDims = 126;
inline constexpr int kLocDims = 66;
inline constexpr int kLocOffset = 128;
inline constexpr int kFrameStride = 200;

// A motion as the filter sees it: views into a triplets file's columns.
struct MotionView {
  int64_t frames = 0;
  int joints = 0;                    // rotations per frame in `poses` (the first 22 are used)
  const float* poses = nullptr;      // [frames, joints, 3] axis-angle
  const float* trans = nullptr;      // [frames, 3]
  int position_joints = 0;           // 0 when absent
  const float* positions = nullptr;  // [frames, position_joints, 3]
};

// Row `row` of one side of a triplets file's columns.
MotionView SideView(const TripletColumns::Side& side, int64_t row);

// Fills `out` ([frames, kFrameStride]) with both branches. `use_stored` takes positions - trans,
// otherwise FK. The caller has checked shapes and finiteness.
void BranchFeatures(const MotionView& motion, bool use_stored, std::vector<float>* out);

// Eq. (4) for both branches at once: raw_rot[i] = S_i^Rr, raw_loc[i] = S_i^Rl.
void RawSimilarity(const float* source, int64_t source_frames, const float* target,
                   int64_t target_frames, int window, double* raw_rot, double* raw_loc);
// numpy.convolve(x, ones(m) / m, 'same') for len(x) >= m: out[i] = mean of x[i - m + 1 + (m-1)/2 ..
// i + (m-1)/2], values outside x counting as 0. Shorter inputs keep their length (numpy would
// return m values).
std::vector<double> MovingAverage(const std::vector<double>& x, int m);
// Eq. (9) on a similarity curve (distances are -S). +inf when the smallest distances are all 0 but
// the largest are not; NaN when every distance is 0 (identical motions: no signal).
double MotionSnr(const std::vector<double>& similarity, int kappa);
// Eq. (6); false (and `out` untouched) when the curve is flat.
bool MinMaxNormalize(const std::vector<double>& curve, std::vector<double>* out);
// Eq. (10).
uint8_t Quantize(double normalized, int classes);

enum class DropReason {
  kNone,
  kBadShape,
  kNonFinite,
  kEmpty,
  kOneFrame,
  kTooShort,
  kNoSignal,
  kLowSnr
};
const char* DropReasonName(DropReason reason);

struct SimilarityResult {
  DropReason dropped = DropReason::kNone;
  std::string detail;              // why, for the dropped list
  double snr = 0;                  // eq. (9); NaN when not computed
  std::vector<double> raw_rot;     // eq. (4), rotation branch, before smoothing
  std::vector<double> raw_loc;     // eq. (4), location branch, before smoothing
  std::vector<double> combined;    // eq. (5) after smoothing: S^R
  std::vector<double> normalized;  // eq. (6): S^N
  std::vector<uint8_t> classes;    // eq. (10); empty in regression mode
  bool kept() const { return dropped == DropReason::kNone; }
};

// Scratch buffers reused across triplets by one thread.
struct Workspace {
  std::vector<float> source, target;
};

// The whole computation for one triplet, with every check: bad input is a drop with a reason, never
// an exception.
SimilarityResult ComputeSimilarity(const MotionView& source, const MotionView& target,
                                   const SimilarityOptions& options, Workspace* workspace);

}  // namespace motionpipe::similarity
