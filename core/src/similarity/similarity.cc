#include "motionpipe/similarity/similarity.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "../simd/simd.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::similarity {

static_assert(kFrameStride == simd::kFrameStride && kLocOffset == simd::kLocOffset &&
                  kRotDims == simd::kRotDims && kLocDims == simd::kLocDims,
              "the kernels and the filter must agree on the frame layout");

namespace {

// Index of the first non-finite value (the slow path, once something is known to be wrong).
int64_t FirstNonFinite(const float* values, int64_t n) {
  for (int64_t k = 0; k < n; ++k) {
    if (!std::isfinite(values[k])) return k;
  }
  return -1;
}

// Checks one motion; fills `reason`/`detail` on failure.
bool CheckMotion(const MotionView& m, const char* side, const SimilarityOptions& options,
                 DropReason* reason, std::string* detail) {
  const std::string who = side;
  if (m.frames == 0) {
    *reason = DropReason::kEmpty;
    *detail = who + " motion has no frames";
    return false;
  }
  if (m.joints < kNumJoints) {
    *reason = DropReason::kBadShape;
    *detail = who + " poses have " + std::to_string(m.joints) +
              " joints; the 22 SMPL body joints are needed";
    return false;
  }
  struct Array {
    const float* values;
    int64_t count;
    int per_frame;
    const char* what;
  };
  for (const Array& a : {Array{m.poses, m.frames * m.joints * 3, m.joints * 3, " poses"},
                         Array{m.trans, m.frames * 3, 3, " translation"},
                         Array{m.positions, m.positions ? m.frames * m.position_joints * 3 : 0,
                               std::max(1, m.position_joints * 3), " joint positions"}}) {
    if (a.count == 0 || simd::AllFinite(a.values, a.count)) continue;
    *reason = DropReason::kNonFinite;
    *detail = who + a.what + " hold NaN/Inf at frame " +
              std::to_string(FirstNonFinite(a.values, a.count) / a.per_frame);
    return false;
  }
  if (m.frames == 1) {
    *reason = DropReason::kOneFrame;
    *detail = who + " motion has a single frame";
    return false;
  }
  if (m.frames < options.min_frames) {
    *reason = DropReason::kTooShort;
    *detail = who + " motion has " + std::to_string(m.frames) +
              " frames, fewer than min_frames = " + std::to_string(options.min_frames);
    return false;
  }
  return true;
}

}  // namespace

const char* LocationSourceName(LocationSource source) {
  switch (source) {
    case LocationSource::kAuto:
      return "auto";
    case LocationSource::kStored:
      return "stored";
    case LocationSource::kForwardKinematics:
      return "fk";
  }
  return "?";
}

const char* DropReasonName(DropReason reason) {
  switch (reason) {
    case DropReason::kNone:
      return "kept";
    case DropReason::kBadShape:
      return "bad_shape";
    case DropReason::kNonFinite:
      return "non_finite";
    case DropReason::kEmpty:
      return "empty";
    case DropReason::kOneFrame:
      return "one_frame";
    case DropReason::kTooShort:
      return "too_short";
    case DropReason::kNoSignal:
      return "no_signal";
    case DropReason::kLowSnr:
      return "low_snr";
  }
  return "?";
}

Result<SimilarityOptions> SimilarityPreset(const std::string& name) {
  SimilarityOptions options;
  if (name == "paper") return options;
  if (name == "reference") {
    options.kappa = 10;  // REFERENCE section 7: the authors' script uses the 10 extreme frames
    return options;
  }
  return InvalidArgument("unknown similarity preset '" + name + "' (known: paper, reference)");
}

Status ValidateOptions(const SimilarityOptions& o, const std::string& origin) {
  auto bad = [&](const std::string& key, const std::string& why) {
    return InvalidArgument(origin + ": " + key + ": " + why);
  };
  if (o.window < 1) return bad("window", "must be >= 1 (got " + std::to_string(o.window) + ")");
  if (o.smooth < 1) return bad("smooth", "must be >= 1 (1 = no smoothing)");
  if (!(o.w_rot >= 0) || !(o.w_loc >= 0) || !(o.w_rot + o.w_loc > 0)) {
    return bad("w_rot/w_loc", "weights must be >= 0 and not both 0");
  }
  if (o.kappa < 1) return bad("kappa", "must be >= 1");
  if (!(o.snr_threshold >= 0)) return bad("snr_threshold", "must be >= 0");
  if (o.min_frames < 2) return bad("min_frames", "must be >= 2");
  if (o.classes != 0 && (o.classes < 2 || o.classes > 255))
    return bad("classes", "must be 0 (regression) or 2..255");
  return Status::Ok();
}

Result<SimilarityOptions> OptionsFromJson(const nlohmann::json& config, const std::string& origin,
                                          const std::vector<std::string>& ignore) {
  if (!config.is_object())
    return InvalidArgument(origin + ": similarity options must be a mapping");
  SimilarityOptions options;
  if (config.contains("preset")) {
    if (!config["preset"].is_string())
      return InvalidArgument(origin + ": preset: must be a string");
    auto preset = SimilarityPreset(config["preset"].get<std::string>());
    if (!preset.ok()) return InvalidArgument(origin + ": preset: " + preset.status().message());
    options = *preset;
  }
  for (const auto& item : config.items()) {
    const std::string key = item.key();
    const nlohmann::json& value = item.value();
    auto need_int = [&](int* field) -> Status {
      if (!value.is_number_integer())
        return InvalidArgument(origin + ": " + key + ": must be an integer");
      *field = value.get<int>();
      return Status::Ok();
    };
    auto need_number = [&](double* field) -> Status {
      if (!value.is_number()) return InvalidArgument(origin + ": " + key + ": must be a number");
      *field = value.get<double>();
      return Status::Ok();
    };
    if (key == "preset") continue;
    if (key == "window") {
      MP_RETURN_IF_ERROR(need_int(&options.window));
    } else if (key == "smooth") {
      MP_RETURN_IF_ERROR(need_int(&options.smooth));
    } else if (key == "w_rot") {
      MP_RETURN_IF_ERROR(need_number(&options.w_rot));
    } else if (key == "w_loc") {
      MP_RETURN_IF_ERROR(need_number(&options.w_loc));
    } else if (key == "kappa") {
      MP_RETURN_IF_ERROR(need_int(&options.kappa));
    } else if (key == "snr_threshold") {
      MP_RETURN_IF_ERROR(need_number(&options.snr_threshold));
    } else if (key == "min_frames") {
      MP_RETURN_IF_ERROR(need_int(&options.min_frames));
    } else if (key == "classes") {
      if (value.is_string() && value.get<std::string>() == "regression") {
        options.classes = 0;
      } else {
        MP_RETURN_IF_ERROR(need_int(&options.classes));
      }
    } else if (key == "locations") {
      const std::string text = value.is_string() ? value.get<std::string>() : "";
      if (text == "auto") {
        options.locations = LocationSource::kAuto;
      } else if (text == "stored") {
        options.locations = LocationSource::kStored;
      } else if (text == "fk") {
        options.locations = LocationSource::kForwardKinematics;
      } else {
        return InvalidArgument(origin + ": locations: must be auto, stored or fk");
      }
    } else if (std::find(ignore.begin(), ignore.end(), key) == ignore.end()) {
      return InvalidArgument(origin + ": unknown key '" + key +
                             "' (known: preset, window, smooth, w_rot, w_loc, kappa, "
                             "snr_threshold, min_frames, classes, locations)");
    }
  }
  MP_RETURN_IF_ERROR(ValidateOptions(options, origin));
  return options;
}

nlohmann::json OptionsToJson(const SimilarityOptions& o) {
  return {{"window", o.window},
          {"smooth", o.smooth},
          {"w_rot", o.w_rot},
          {"w_loc", o.w_loc},
          {"kappa", o.kappa},
          {"snr_threshold", o.snr_threshold},
          {"min_frames", o.min_frames},
          {"classes", o.classes},
          {"locations", LocationSourceName(o.locations)}};
}

MotionView SideView(const TripletColumns::Side& side, int64_t row) {
  MotionView m;
  const int64_t f0 = side.offsets[static_cast<size_t>(row)];
  m.frames = side.offsets[static_cast<size_t>(row) + 1] - f0;
  m.joints = side.joints;
  m.poses = side.poses + f0 * side.joints * 3;
  m.trans = side.trans + f0 * 3;
  if (side.position_joints > 0) {
    m.position_joints = side.position_joints;
    m.positions = side.positions + f0 * side.position_joints * 3;
  }
  return m;
}

void BranchFeatures(const MotionView& motion, bool use_stored, std::vector<float>* out) {
  const int64_t frames = motion.frames;
  const int64_t n = frames * kNumJoints;
  out->resize(static_cast<size_t>(frames * kFrameStride));
  float* features = out->data();
  // Everything below works on joint-major planes (joint j, frame f at j * frames + f) so that the
  // kernels vectorise along time; only the body's 22 joints are used when poses carry more. The
  // layout changes are blocked 8 x 8 transposes.
  thread_local std::vector<float> scratch;
  scratch.resize(static_cast<size_t>(n * (3 + 9 + 9 + 3)));
  float* axis = scratch.data();  // [(3 j + a) T + f]
  float* local = axis + 3 * n;   // [k n + j T + f]
  float* global = local + 9 * n;
  float* positions = global + 9 * n;  // [(3 j + a) T + f]
  simd::Transpose(motion.poses, motion.joints * 3, frames, 3 * kNumJoints, axis, frames);
  for (int j = 0; j < kNumJoints; ++j) {
    const float* a = axis + 3 * j * frames;
    // Nine output planes of this joint: the kernel writes element k at out + k * n.
    simd::AxisAngleToMatrices(a, a + frames, a + 2 * frames, frames, local + j * frames, n);
  }
  // Rotation branch: 6D (first two rows) of joints 1..21, element-major within the frame (entry k
  // of joints 1..21 at [21 k, 21 k + 21)); the L1 distance does not depend on the order.
  for (int k = 0; k < 6; ++k) {
    simd::Transpose(local + k * n + frames, frames, kNumJoints - 1, frames,
                    features + k * (kNumJoints - 1), kFrameStride);
  }
  for (int64_t f = 0; f < frames; ++f) {
    float* row = features + f * kFrameStride;
    for (int d = kRotDims; d < kLocOffset; ++d) row[d] = 0.f;
    for (int d = kLocOffset + kLocDims; d < kFrameStride; ++d) row[d] = 0.f;
  }
  // Location branch: joint positions with the pelvis translation removed.
  if (use_stored) {
    for (int64_t f = 0; f < frames; ++f) {
      float* loc = features + f * kFrameStride + kLocOffset;
      const float* pos = motion.positions + f * motion.position_joints * 3;
      const float* t = motion.trans + f * 3;
      for (int j = 0; j < kNumJoints; ++j) {
        for (int d = 0; d < 3; ++d) loc[3 * j + d] = pos[3 * j + d] - t[d];
      }
    }
    return;
  }
  const simd::SkeletonArrays& skeleton = simd::TemplateSkeleton();
  simd::ForwardKinematics(local, frames, skeleton.parents, skeleton.offsets, global, positions);
  simd::Transpose(positions, frames, 3 * kNumJoints, frames, features + kLocOffset, kFrameStride);
}

void RawSimilarity(const float* source, int64_t source_frames, const float* target,
                   int64_t target_frames, int window, double* raw_rot, double* raw_loc) {
  simd::RawSimilarity(source, source_frames, target, target_frames, window, raw_rot, raw_loc);
}

std::vector<double> MovingAverage(const std::vector<double>& x, int m) {
  const auto n = static_cast<int64_t>(x.size());
  std::vector<double> out(x.size(), 0.0);
  if (m <= 1) return x;
  // numpy 'same' keeps the centre of the full convolution: out[i] = full[i + (m - 1) / 2], and
  // full[k] sums x[k - m + 1 .. k]. A running sum over the window.
  const int64_t shift = (m - 1) / 2;
  auto at = [&](int64_t k) { return k >= 0 && k < n ? x[static_cast<size_t>(k)] : 0.0; };
  double sum = 0;
  for (int64_t k = -m + 1 + shift; k <= shift; ++k) sum += at(k);
  for (int64_t i = 0; i < n; ++i) {
    out[static_cast<size_t>(i)] = sum / m;
    sum += at(i + shift + 1) - at(i + shift + 1 - m);
  }
  return out;
}

double MotionSnr(const std::vector<double>& similarity, int kappa) {
  std::vector<double> distance(similarity.size());
  std::transform(similarity.begin(), similarity.end(), distance.begin(),
                 [](double s) { return -s; });
  const auto k =
      static_cast<ptrdiff_t>(std::min<size_t>(static_cast<size_t>(kappa), distance.size()));
  if (k == 0) return std::numeric_limits<double>::quiet_NaN();
  // Eq. (7)-(8): the kappa largest and the kappa smallest distances.
  std::nth_element(distance.begin(), distance.begin() + k - 1, distance.end());
  double smallest = 0;
  for (ptrdiff_t i = 0; i < k; ++i) smallest += distance[static_cast<size_t>(i)];
  std::nth_element(distance.begin(), distance.end() - k, distance.end());
  double largest = 0;
  for (auto it = distance.end() - k; it != distance.end(); ++it) largest += *it;
  if (smallest <= 0)
    return largest > 0 ? std::numeric_limits<double>::infinity()
                       : std::numeric_limits<double>::quiet_NaN();
  return largest / smallest;  // the kappa's cancel: a ratio of means
}

bool MinMaxNormalize(const std::vector<double>& curve, std::vector<double>* out) {
  if (curve.empty()) return false;
  const auto [lo, hi] = std::minmax_element(curve.begin(), curve.end());
  const double range = *hi - *lo;
  if (!(range > 0)) return false;
  out->resize(curve.size());
  const double low = *lo;
  for (size_t i = 0; i < curve.size(); ++i) (*out)[i] = (curve[i] - low) / range;
  return true;
}

uint8_t Quantize(double normalized, int classes) {
  const double bin = std::floor(normalized * classes);
  return static_cast<uint8_t>(std::clamp(bin, 0.0, static_cast<double>(classes - 1)));
}

SimilarityResult ComputeSimilarity(const MotionView& source, const MotionView& target,
                                   const SimilarityOptions& options, Workspace* workspace) {
  SimilarityResult result;
  result.snr = std::numeric_limits<double>::quiet_NaN();
  if (!CheckMotion(source, "source", options, &result.dropped, &result.detail) ||
      !CheckMotion(target, "target", options, &result.dropped, &result.detail)) {
    return result;
  }
  if (source.joints != target.joints) {
    result.dropped = DropReason::kBadShape;
    result.detail = "source has " + std::to_string(source.joints) + " joints, target " +
                    std::to_string(target.joints);
    return result;
  }
  const bool both_stored = source.positions && target.positions &&
                           source.position_joints >= kNumJoints &&
                           target.position_joints >= kNumJoints;
  bool use_stored = false;
  switch (options.locations) {
    case LocationSource::kAuto:
      use_stored = both_stored;
      break;
    case LocationSource::kForwardKinematics:
      use_stored = false;
      break;
    case LocationSource::kStored:
      if (!both_stored) {
        result.dropped = DropReason::kBadShape;
        result.detail =
            "locations: stored, but the triplet has no stored positions of the 22 body joints";
        return result;
      }
      use_stored = true;
      break;
  }
  if (use_stored && source.position_joints != target.position_joints) {
    result.dropped = DropReason::kBadShape;
    result.detail = "source positions have " + std::to_string(source.position_joints) +
                    " joints, target " + std::to_string(target.position_joints);
    return result;
  }

  BranchFeatures(source, use_stored, &workspace->source);
  BranchFeatures(target, use_stored, &workspace->target);
  const auto ts = static_cast<size_t>(source.frames);
  result.raw_rot.resize(ts);
  result.raw_loc.resize(ts);
  RawSimilarity(workspace->source.data(), source.frames, workspace->target.data(), target.frames,
                options.window, result.raw_rot.data(), result.raw_loc.data());
  // Eq. (5) on the smoothed branches.
  const std::vector<double> rot = MovingAverage(result.raw_rot, options.smooth);
  const std::vector<double> loc = MovingAverage(result.raw_loc, options.smooth);
  result.combined.resize(ts);
  for (size_t i = 0; i < ts; ++i)
    result.combined[i] = options.w_rot * rot[i] + options.w_loc * loc[i];

  result.snr = MotionSnr(result.combined, options.kappa);
  if (std::isnan(result.snr) || !MinMaxNormalize(result.combined, &result.normalized)) {
    result.dropped = DropReason::kNoSignal;
    result.detail = "source and target agree everywhere: the similarity curve is flat";
    return result;
  }
  if (result.snr < options.snr_threshold) {
    result.dropped = DropReason::kLowSnr;
    char text[96];
    std::snprintf(text, sizeof text, "MotionSNR %.4g < threshold %.4g", result.snr,
                  options.snr_threshold);
    result.detail = text;
    return result;
  }
  if (options.classes > 0) {
    result.classes.resize(ts);
    for (size_t i = 0; i < ts; ++i)
      result.classes[i] = Quantize(result.normalized[i], options.classes);
  }
  return result;
}

}  // namespace motionpipe::similarity
