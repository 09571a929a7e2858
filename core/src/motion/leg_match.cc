#include "motionpipe/motion/leg_match.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

#include "motionpipe/base/options.h"
#include "motionpipe/base/random.h"

namespace motionpipe {

namespace {

constexpr int kPathFeatures = 4;  // velocity x, y in the heading frame, turning speed, height
constexpr int kPlacedJoints = 4;  // knees and ankles
constexpr int kFeatures = kPathFeatures + 3 * kPlacedJoints;

// Per side: hip, knee, ankle, toe (from the skeleton's foot joints and their parents).
std::array<std::array<int, 4>, 2> LegJoints(const Skeleton& skeleton) {
  std::array<std::array<int, 4>, 2> legs{};
  const std::array<std::array<int, 2>, 2> feet = {skeleton.left_foot_joints(),
                                                  skeleton.right_foot_joints()};
  for (size_t side = 0; side < 2; ++side) {
    const int ankle = feet[side][0], toe = feet[side][1];
    const int knee = skeleton.parents()[static_cast<size_t>(ankle)];
    legs[side] = {skeleton.parents()[static_cast<size_t>(knee)], knee, ankle, toe};
  }
  return legs;
}

// The knees' and ankles' places relative to the pelvis, heading removed (the features' leg
// columns before the low-pass; the database's join between windows), by forward kinematics from
// the pelvis's local rotation and each leg's hip and knee rotations (left hip, left knee, right
// hip, right knee).
std::array<float, 3 * kPlacedJoints> LegPlaces(const Skeleton& skeleton, const Mat3& pelvis,
                                               const std::array<Mat3, 4>& hips_and_knees) {
  std::array<float, 3 * kPlacedJoints> out{};
  const auto& offsets = skeleton.rest_offsets();
  const Mat3 unturned = RemoveHeading(pelvis);
  size_t c = 0, r = 0;
  for (const auto& leg : LegJoints(skeleton)) {
    Mat3 global = unturned;
    Vec3 place = global * offsets[static_cast<size_t>(leg[0])];
    for (size_t k = 1; k <= 2; ++k) {  // knee, ankle
      global = global * hips_and_knees[r++];
      place = place + global * offsets[static_cast<size_t>(leg[k])];
      out[c++] = static_cast<float>(place.x);
      out[c++] = static_cast<float>(place.y);
      out[c++] = static_cast<float>(place.z);
    }
  }
  return out;
}

// x filtered along time by a Gaussian of sigma frames, the ends repeated ([T, width] rows).
void Smooth(std::vector<float>& x, int64_t frames, int width, int column, int columns,
            double sigma) {
  if (sigma <= 0 || frames < 2) return;
  const int64_t radius = static_cast<int64_t>(std::ceil(3 * sigma));
  std::vector<double> kernel(static_cast<size_t>(2 * radius + 1));
  double total = 0;
  for (int64_t k = -radius; k <= radius; ++k)
    total += kernel[static_cast<size_t>(k + radius)] =
        std::exp(-0.5 * static_cast<double>(k * k) / (sigma * sigma));
  std::vector<float> out(static_cast<size_t>(frames * width));
  for (int64_t t = 0; t < frames; ++t)
    for (int c = 0; c < width; ++c) {
      double sum = 0;
      for (int64_t k = -radius; k <= radius; ++k) {
        const int64_t s = std::clamp<int64_t>(t + k, 0, frames - 1);
        sum += kernel[static_cast<size_t>(k + radius)] *
               x[static_cast<size_t>(s * columns + column + c)];
      }
      out[static_cast<size_t>(t * width + c)] = static_cast<float>(sum / total);
    }
  for (int64_t t = 0; t < frames; ++t)
    for (int c = 0; c < width; ++c)
      x[static_cast<size_t>(t * columns + column + c)] = out[static_cast<size_t>(t * width + c)];
}

// The mean angle (degrees) between two motions' leg-joint local rotations (hips, knees, ankles).
double LegChangeDegrees(const Skeleton& skeleton, const Motion& a, const Motion& b) {
  double sum = 0;
  int64_t count = 0;
  for (const auto& leg : LegJoints(skeleton))
    for (int k = 0; k < 3; ++k)
      for (int64_t f = 0; f < a.num_frames(); ++f) {
        const Mat3 r = Transpose(a.LocalRotation(f, leg[static_cast<size_t>(k)])) *
                       b.LocalRotation(f, leg[static_cast<size_t>(k)]);
        const double c = std::clamp((r.m[0][0] + r.m[1][1] + r.m[2][2] - 1) / 2, -1.0, 1.0);
        sum += std::acos(c) * 180 / std::numbers::pi;
        ++count;
      }
  return count > 0 ? sum / static_cast<double>(count) : 0.0;
}

}  // namespace

std::vector<float> LegMatchFeatures(const Skeleton& skeleton, const Motion& motion,
                                    double sigma_seconds) {
  const int64_t frames = motion.num_frames();
  std::vector<float> out(static_cast<size_t>(frames * kFeatures), 0.0f);
  if (frames == 0) return out;
  std::vector<double> heading(static_cast<size_t>(frames));
  for (int64_t f = 0; f < frames; ++f) {
    heading[static_cast<size_t>(f)] = HeadingZYX(motion.LocalRotation(f, 0));
    if (f > 0) {  // unwrapped
      double& h = heading[static_cast<size_t>(f)];
      const double previous = heading[static_cast<size_t>(f - 1)];
      while (h - previous > std::numbers::pi) h -= 2 * std::numbers::pi;
      while (h - previous < -std::numbers::pi) h += 2 * std::numbers::pi;
    }
  }
  // Central differences (one-sided at the ends), per second.
  const auto derivative = [&](int64_t f, const auto& value) {
    const int64_t a = std::max<int64_t>(f - 1, 0), b = std::min(f + 1, frames - 1);
    return b > a ? (value(b) - value(a)) * (motion.fps / static_cast<double>(b - a)) : 0.0;
  };
  const auto legs = LegJoints(skeleton);
  for (int64_t f = 0; f < frames; ++f) {
    float* row = &out[static_cast<size_t>(f * kFeatures)];
    const Mat3 unturn = RotZ(-heading[static_cast<size_t>(f)]);
    const Vec3 velocity =
        unturn * Vec3{derivative(f, [&](int64_t g) { return motion.Translation(g).x; }),
                      derivative(f, [&](int64_t g) { return motion.Translation(g).y; }), 0.0};
    row[0] = static_cast<float>(velocity.x);
    row[1] = static_cast<float>(velocity.y);
    row[2] = static_cast<float>(
        derivative(f, [&](int64_t g) { return heading[static_cast<size_t>(g)]; }));
    row[3] = static_cast<float>(motion.Translation(f).z);
    const auto places =
        LegPlaces(skeleton, motion.LocalRotation(f, 0),
                  {motion.LocalRotation(f, legs[0][0]), motion.LocalRotation(f, legs[0][1]),
                   motion.LocalRotation(f, legs[1][0]), motion.LocalRotation(f, legs[1][1])});
    std::copy(places.begin(), places.end(), row + kPathFeatures);
  }
  Smooth(out, frames, 3 * kPlacedJoints, kPathFeatures, kFeatures, sigma_seconds * motion.fps);
  return out;
}

nlohmann::json LegMatchOptionsToJson(const LegMatchOptions& o) {
  return {{"sigma_seconds", o.sigma_seconds},
          {"legs_weight", o.legs_weight},
          {"frame_step", o.frame_step},
          {"match_pelvis", o.match_pelvis},
          {"random", o.random},
          {"seed", o.seed}};
}

Result<LegMatchOptions> LegMatchOptionsFromJson(const nlohmann::json& p, const std::string& origin,
                                                const std::vector<std::string>& other_keys) {
  LegMatchOptions o;
  if (Status s =
          CheckOptionKeys(p, LegMatchOptionsToJson(o), origin, "leg-matching options", other_keys);
      !s.ok())
    return s;
  try {
    o.sigma_seconds = p.value("sigma_seconds", o.sigma_seconds);
    o.legs_weight = p.value("legs_weight", o.legs_weight);
    o.frame_step = p.value("frame_step", o.frame_step);
    o.match_pelvis = p.value("match_pelvis", o.match_pelvis);
    o.random = p.value("random", o.random);
    o.seed = p.value("seed", o.seed);
  } catch (const nlohmann::json::exception& e) {
    return InvalidArgument(origin + ": " + e.what());
  }
  if (!(o.sigma_seconds >= 0)) return InvalidArgument(origin + ".sigma_seconds: must be >= 0 s");
  if (!(o.legs_weight >= 0)) return InvalidArgument(origin + ".legs_weight: must be >= 0");
  if (o.frame_step < 1) return InvalidArgument(origin + ".frame_step: must be >= 1");
  return o;
}

void LegMatchReport::Add(const LegMatchReport& other) {
  matched += other.matched;
  windows += other.windows;
  cost += other.cost;
  degrees += other.degrees;
}

LegDatabase::LegDatabase(const Skeleton& skeleton, const LegMatchOptions& options)
    : skeleton_(&skeleton), options_(options) {}

std::array<float, LegDatabase::kPlaces> LegDatabase::PlacesOf(const float* pelvis,
                                                              const float* legs) const {
  const auto rotation = [&](int side, int k) {  // legs: per side hip, knee, ankle, toe
    const float* r = legs + 12 * side + 3 * k;
    return AxisAngleToMatrix({r[0], r[1], r[2]});
  };
  return LegPlaces(*skeleton_, AxisAngleToMatrix({pelvis[0], pelvis[1], pelvis[2]}),
                   {rotation(0, 0), rotation(0, 1), rotation(1, 0), rotation(1, 1)});
}

std::array<float, LegDatabase::kPlaces> LegDatabase::PlacesAt(int64_t frame) const {
  return PlacesOf(&pelvis_[static_cast<size_t>(frame * 3)],
                  &legs_[static_cast<size_t>(frame * 24)]);
}

Status LegDatabase::Add(const Motion& motion, const std::string& origin) {
  if (!weights_.empty())
    return FailedPrecondition("leg matching: " + origin + " added after the first match");
  MP_ASSIGN_OR_RETURN(Rows rows, Prepare(motion, origin));
  return Append(std::move(rows));
}

Result<LegDatabase::Rows> LegDatabase::Prepare(const Motion& motion,
                                               const std::string& origin) const {
  if (Status s = ValidateMotion(motion, origin); !s.ok()) return InvalidArgument(s.message());
  const int64_t T = motion.num_frames(), step = options_.frame_step;
  Rows rows;
  rows.origin = origin;
  rows.fps = motion.fps;
  rows.frames = T;
  const std::vector<float> f = LegMatchFeatures(*skeleton_, motion, options_.sigma_seconds);
  for (int64_t t = 0; t < T; t += step)
    rows.features.insert(rows.features.end(), f.begin() + t * kFeatures,
                         f.begin() + (t + 1) * kFeatures);
  const auto legs = LegJoints(*skeleton_);
  rows.legs.reserve(static_cast<size_t>(T * 24));
  for (int64_t t = 0; t < T; ++t) {
    for (const auto& leg : legs)
      for (int joint : leg)
        for (int c = 0; c < 3; ++c)
          rows.legs.push_back(motion.poses[static_cast<size_t>((t * kNumJoints + joint) * 3 + c)]);
    for (int c = 0; c < 3; ++c)
      rows.pelvis.push_back(motion.poses[static_cast<size_t>(t * kNumJoints * 3 + c)]);
    rows.height.push_back(static_cast<float>(motion.Translation(t).z));
  }
  for (int64_t t = 0; t < T; t += step) {
    const auto places =
        PlacesOf(&rows.pelvis[static_cast<size_t>(t * 3)], &rows.legs[static_cast<size_t>(t * 24)]);
    rows.places.insert(rows.places.end(), places.begin(), places.end());
  }
  return rows;
}

Status LegDatabase::Append(Rows rows) {
  if (!weights_.empty())
    return FailedPrecondition("leg matching: " + rows.origin + " added after the first match");
  if (length_.empty()) fps_ = rows.fps;
  if (!SameFrameRate(rows.fps, fps_))
    return InvalidArgument(rows.origin + ": at " + std::to_string(rows.fps) +
                           " fps where the database's first motion is at " + std::to_string(fps_) +
                           " (resample them to one rate)");
  length_.push_back(rows.frames);
  first_frame_.push_back(frames());
  first_compared_.push_back(static_cast<int64_t>(features_.size() / kFeatures));
  const auto append = [](std::vector<float>& to, const std::vector<float>& from) {
    to.insert(to.end(), from.begin(), from.end());
  };
  append(features_, rows.features);
  append(places_, rows.places);
  append(legs_, rows.legs);
  append(pelvis_, rows.pelvis);
  append(height_, rows.height);
  longest_ = std::max(longest_, rows.frames);
  return Status::Ok();
}

void LegDatabase::Weigh() {
  // Each feature scaled by its spread over the database; the groups weighted alike.
  std::array<double, kFeatures> mean{}, square{};
  const int64_t rows = static_cast<int64_t>(features_.size() / kFeatures);
  for (int64_t r = 0; r < rows; ++r)
    for (int c = 0; c < kFeatures; ++c) {
      const double x = features_[static_cast<size_t>(r * kFeatures + c)];
      mean[static_cast<size_t>(c)] += x / static_cast<double>(rows);
      square[static_cast<size_t>(c)] += x * x / static_cast<double>(rows);
    }
  for (int c = 0; c < kFeatures; ++c) {
    const double m = mean[static_cast<size_t>(c)];
    const double spread = std::sqrt(std::max(square[static_cast<size_t>(c)] - m * m, 0.0)) + 1e-6;
    const double group = c < kPathFeatures ? 1.0 / kPathFeatures
                                           : options_.legs_weight / (kFeatures - kPathFeatures);
    weights_.push_back(static_cast<float>(group / (spread * spread)));
  }
}

LegDatabase::Choice LegDatabase::Nearest(const std::vector<float>& query,
                                         const std::vector<float>& joined, int64_t T) const {
  const int64_t step = options_.frame_step;
  const int64_t compared = static_cast<int64_t>(query.size() / kFeatures);
  const int64_t joins = static_cast<int64_t>(joined.size() / kPlaces);
  const float* w = weights_.data();
  const float* wp =
      w + kPathFeatures;  // the leg places' weights, for the join with the last window
  Choice best;
  for (int64_t m = 0; m < motions(); ++m) {
    const int64_t length = length_[static_cast<size_t>(m)];
    const size_t first = static_cast<size_t>(first_compared_[static_cast<size_t>(m)]);
    const float* base = &features_[first * kFeatures];
    const float* places = &places_[first * kPlaces];
    for (int64_t k = 0; k * step + T <= length; ++k) {
      double cost = 0;  // abandoned once it exceeds the best
      for (int64_t j = 0; j < compared && cost < best.cost; ++j) {
        const float* a = &query[static_cast<size_t>(j * kFeatures)];
        const float* b = base + (k + j) * kFeatures;
        float sum = 0;
        for (int c = 0; c < kFeatures; ++c) sum += w[c] * (a[c] - b[c]) * (a[c] - b[c]);
        if (j < joins) {
          const float* x = &joined[static_cast<size_t>(j * kPlaces)];
          const float* y = places + (k + j) * kPlaces;
          for (int c = 0; c < kPlaces; ++c) sum += wp[c] * (x[c] - y[c]) * (x[c] - y[c]);
        }
        cost += sum;
      }
      if (cost < best.cost) best = {m, k * step, cost};
    }
  }
  best.cost /= static_cast<double>(compared);  // per compared frame
  return best;
}

LegDatabase::Choice LegDatabase::Drawn(int64_t T) {
  const int64_t step = options_.frame_step;
  const auto windows = [&](int64_t m) {
    const int64_t length = length_[static_cast<size_t>(m)];
    return length >= T ? (length - T) / step + 1 : 0;
  };
  int64_t all = 0;
  for (int64_t m = 0; m < motions(); ++m) all += windows(m);
  Rng rng(MixSeed(options_.seed, draws_++));
  int64_t pick = std::min(all - 1, static_cast<int64_t>(rng.Uniform() * static_cast<double>(all)));
  for (int64_t m = 0; m < motions(); ++m) {
    if (pick < windows(m)) return {m, pick * step, 0.0};
    pick -= windows(m);
  }
  return {};
}

Result<Motion> LegDatabase::Match(const Motion& motion, LegMatchReport* report) {
  if (length_.empty()) return FailedPrecondition("leg matching: the database holds no motion");
  if (Status s = ValidateMotion(motion, "leg matching"); !s.ok())
    return InvalidArgument(s.message());
  if (!SameFrameRate(motion.fps, fps_))
    return InvalidArgument("leg matching: a motion at " + std::to_string(motion.fps) +
                           " fps, the database's motions at " + std::to_string(fps_));
  if (weights_.empty()) Weigh();
  const int64_t T = motion.num_frames(), step = options_.frame_step;
  // Windows of the longest database motion's length (the whole motion when it fits), each half
  // over the last, the last ending with the motion; a window's choice also weighs how near its leg
  // places come to the last window's over their common frames, and the legs are blended there.
  const int64_t W = std::min(T, longest_);
  const int64_t hop = std::max(step, (W / 2) / step * step);
  std::vector<int64_t> starts = {0};
  while (starts.back() + W < T) starts.push_back(std::min(starts.back() + hop, T - W));
  const std::vector<float> features = LegMatchFeatures(*skeleton_, motion, options_.sigma_seconds);
  LegMatchReport one;
  Motion out = motion;
  const auto legs = LegJoints(*skeleton_);
  Choice last;
  for (size_t i = 0; i < starts.size(); ++i) {
    const int64_t s = starts[i];
    Choice chosen;
    if (options_.random) {
      chosen = Drawn(W);
    } else {
      std::vector<float> query, joined;
      for (int64_t t = 0; t < W; t += step) {
        query.insert(query.end(), features.begin() + (s + t) * kFeatures,
                     features.begin() + (s + t + 1) * kFeatures);
        if (i > 0 && s + t < starts[i - 1] + W) {
          const auto places = PlacesAt(first_frame_[static_cast<size_t>(last.motion)] + last.start +
                                       (s + t - starts[i - 1]));
          joined.insert(joined.end(), places.begin(), places.end());
        }
      }
      chosen = Nearest(query, joined, W);
    }
    const int64_t first = first_frame_[static_cast<size_t>(chosen.motion)] + chosen.start;
    // Over the frames shared with the last window, its legs fade into this one's.
    const int64_t shared = i > 0 ? starts[i - 1] + W - s : 0;
    for (int64_t t = 0; t < W; ++t) {
      const int64_t f = s + t;
      const double weight =
          t < shared ? static_cast<double>(t + 1) / static_cast<double>(shared + 1) : 1.0;
      const float* row = &legs_[static_cast<size_t>((first + t) * 24)];
      for (const auto& leg : legs)
        for (int joint : leg) {
          if (weight < 1) {  // slerp from what the last window wrote
            const Quat q = Slerp(MatrixToQuat(out.LocalRotation(f, joint)),
                                 AxisAngleToQuat({row[0], row[1], row[2]}), weight);
            out.SetLocalRotation(f, joint, QuatToMatrix(q));
          } else {
            std::copy(row, row + 3, &out.poses[static_cast<size_t>((f * kNumJoints + joint) * 3)]);
          }
          row += 3;
        }
      if (options_.match_pelvis) {
        // The matched pelvis's tilt under the motion's own heading, and its height.
        const float* p = &pelvis_[static_cast<size_t>((first + t) * 3)];
        const Mat3 matched = AxisAngleToMatrix({p[0], p[1], p[2]});
        const double turn = HeadingZYX(motion.LocalRotation(f, 0)) - HeadingZYX(matched);
        Mat3 pelvis = RotZ(turn) * matched;
        Vec3 position = out.Translation(f);
        const double z = height_[static_cast<size_t>(first + t)];
        if (weight < 1) {
          pelvis = QuatToMatrix(
              Slerp(MatrixToQuat(out.LocalRotation(f, 0)), MatrixToQuat(pelvis), weight));
          position.z += weight * (z - position.z);
        } else {
          position.z = z;
        }
        out.SetLocalRotation(f, 0, pelvis);
        out.SetTranslation(f, position);
      }
    }
    one.cost += chosen.cost / static_cast<double>(starts.size());
    last = chosen;
  }
  one.matched = 1;
  one.windows = static_cast<int64_t>(starts.size());
  one.degrees = LegChangeDegrees(*skeleton_, motion, out);
  if (report) report->Add(one);
  return out;
}

}  // namespace motionpipe
