#include "motionpipe/motion/foot_lock.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "motionpipe/base/options.h"

namespace motionpipe {

namespace {

// Where one foot joint is held: per frame a weight (1 inside a contact run, fading to 0 over the
// blend frames beside it) and the run's horizontal place.
struct Hold {
  std::vector<double> weight;
  std::vector<Vec3> place;  // z unused: a held joint keeps its own height
};

// `given` (optional): a model's calls of the frames in contact, which options.given combines with
// the height and speed test.
Hold FindHold(const std::vector<Vec3>& path, double fps, const FootLockOptions& options,
              const std::vector<char>* given, FootLockReport* report) {
  const int64_t frames = static_cast<int64_t>(path.size());
  Hold hold{std::vector<double>(path.size(), 0.0), std::vector<Vec3>(path.size())};
  std::vector<char> contact(path.size(), 0);
  for (int64_t f = 0; f < frames; ++f) {
    // Central difference (one-sided at the ends): a single jittery frame does not split a run.
    const int64_t a = std::max<int64_t>(0, f - 1), b = std::min(frames - 1, f + 1);
    const Vec3 step = path[static_cast<size_t>(b)] - path[static_cast<size_t>(a)];
    const double speed = std::hypot(step.x, step.y) * fps / static_cast<double>(b - a);
    const bool low = path[static_cast<size_t>(f)].z < options.floor + options.contact_height;
    const bool tested = low && speed < options.max_speed;
    if (!given) {
      contact[static_cast<size_t>(f)] = tested;
      continue;
    }
    const bool called = (*given)[static_cast<size_t>(f)] != 0;
    switch (options.given) {
      case GivenContacts::kAlone:
        contact[static_cast<size_t>(f)] = called;
        break;
      case GivenContacts::kNearFloor:
        contact[static_cast<size_t>(f)] = called && low;
        break;
      case GivenContacts::kNearFloorOrTest:
        contact[static_cast<size_t>(f)] = (called && low) || tested;
        break;
    }
  }
  for (int64_t begin = 0; begin < frames;) {
    if (!contact[static_cast<size_t>(begin)]) {
      ++begin;
      continue;
    }
    int64_t end = begin;
    while (end < frames && contact[static_cast<size_t>(end)]) ++end;
    if (end - begin >= options.min_frames) {
      Vec3 place{0, 0, 0};
      for (int64_t f = begin; f < end; ++f) place = place + path[static_cast<size_t>(f)];
      place = (1.0 / static_cast<double>(end - begin)) * place;
      const auto blend = static_cast<int64_t>(std::lround(options.blend_seconds * fps));
      for (int64_t f = std::max<int64_t>(0, begin - blend); f < std::min(frames, end + blend);
           ++f) {
        const int64_t outside = f < begin ? begin - f : (f >= end ? f - end + 1 : 0);
        const double w = 1.0 - static_cast<double>(outside) / static_cast<double>(blend + 1);
        if (w > hold.weight[static_cast<size_t>(f)]) {
          hold.weight[static_cast<size_t>(f)] = w;
          hold.place[static_cast<size_t>(f)] = place;
        }
      }
      if (report) {
        ++report->runs;
        for (int64_t f = begin; f < end; ++f) {
          const Vec3 d = place - path[static_cast<size_t>(f)];
          report->shift += std::hypot(d.x, d.y);
          ++report->held;
        }
      }
    }
    begin = end;
  }
  return hold;
}

// The joint's goal at `frame`: its own position, moved horizontally towards its place by the
// hold's weight.
Vec3 Goal(const Hold& hold, int64_t frame, const Vec3& own) {
  const double w = hold.weight[static_cast<size_t>(frame)];
  const Vec3& place = hold.place[static_cast<size_t>(frame)];
  return {own.x + w * (place.x - own.x), own.y + w * (place.y - own.y), own.z};
}

// A leg reaches at most its length, a hair short of straight (acos stays defined).
constexpr double kReachMargin = 0.9999;

// The pelvis's drop over the motion from each frame's need: widened by 2r frames, then averaged
// twice over r frames on each side (the ends repeated). It is at least the need at every frame
// (every value the averages read at frame f lies within 2r of f) and has no step.
std::vector<double> SmoothLowering(const std::vector<double>& need, int64_t r) {
  const auto frames = static_cast<int64_t>(need.size());
  const auto window = [&](const std::vector<double>& in, int64_t radius, bool widest) {
    std::vector<double> result(in.size(), 0.0);
    for (int64_t f = 0; f < frames; ++f) {
      double acc = 0;
      for (int64_t g = f - radius; g <= f + radius; ++g) {
        const double v = in[static_cast<size_t>(std::clamp<int64_t>(g, 0, frames - 1))];
        acc = widest ? std::max(acc, v) : acc + v / static_cast<double>(2 * radius + 1);
      }
      result[static_cast<size_t>(f)] = acc;
    }
    return result;
  };
  return window(window(window(need, 2 * r, true), r, false), r, false);
}

struct Reached {
  Mat3 g_hip, knee_local;  // the hip's global rotation, the knee's local one
  Vec3 ankle;              // where the ankle ends
};

// Two-bone IK: the hip (H, global rotation g_hip) and knee (K, g_knee) that bring the ankle (A)
// to `wanted`. Out of the leg's reach, the goal comes horizontally towards the hip, at its own
// height: a foot that cannot reach its place slides (and the skate counts it) rather than lift
// off the floor along the hip-to-goal line.
Reached ReachAnkle(const Vec3& H, const Vec3& K, const Vec3& A, const Mat3& g_hip,
                   const Mat3& g_knee, const Vec3& wanted) {
  const double l1 = Norm(K - H), l2 = Norm(A - K);
  Vec3 goal = wanted;
  const double reach = (l1 + l2) * kReachMargin, drop = goal.z - H.z;
  const double across = std::hypot(goal.x - H.x, goal.y - H.y);
  const double across_max = std::sqrt(std::max(0.0, reach * reach - drop * drop));
  if (across > across_max) {
    goal.x = H.x + (goal.x - H.x) * across_max / across;
    goal.y = H.y + (goal.y - H.y) * across_max / across;
  }
  const double d = std::clamp(Norm(goal - H), std::abs(l1 - l2) + 1e-6, reach);
  // The knee's bend (angle between thigh and shin) that puts the ankle at distance d from the
  // hip, by the law of cosines; the knee turns about its bending plane's normal.
  const Vec3 thigh = (1.0 / l1) * (K - H), shin = (1.0 / l2) * (A - K);
  const double bend = std::acos(std::clamp(Dot(thigh, shin), -1.0, 1.0));
  const double wanted_bend =
      std::acos(std::clamp((d * d - l1 * l1 - l2 * l2) / (2 * l1 * l2), -1.0, 1.0));
  Vec3 normal = Cross(thigh, shin);
  // A straight leg has no bending plane: SMPL's knee flexes about its parent's x axis.
  if (Norm(normal) < 1e-6) normal = g_hip * Vec3{1, 0, 0};
  const Mat3 fold = AxisAngleToMatrix(((wanted_bend - bend) / Norm(normal)) * normal);
  const Mat3 knee_local = Transpose(g_hip) * (fold * g_knee);
  const Vec3 folded = K + fold * (A - K);
  // The hip swings by the smallest rotation that points the folded leg at the goal.
  const Mat3 swing = RotationBetween(folded - H, goal - H);
  return {swing * g_hip, knee_local, H + swing * (folded - H)};
}

}  // namespace

nlohmann::json FootLockOptionsToJson(const FootLockOptions& o) {
  return {{"contact_height", o.contact_height},
          {"max_speed", o.max_speed},
          {"min_frames", o.min_frames},
          {"blend_seconds", o.blend_seconds},
          {"lower_pelvis", o.lower_pelvis}};
}

Result<FootLockOptions> FootLockOptionsFromJson(const nlohmann::json& p, const std::string& origin,
                                                const std::vector<std::string>& other_keys) {
  FootLockOptions o;
  if (Status s =
          CheckOptionKeys(p, FootLockOptionsToJson(o), origin, "foot-lock options", other_keys);
      !s.ok())
    return s;
  try {
    o.contact_height = p.value("contact_height", o.contact_height);
    o.max_speed = p.value("max_speed", o.max_speed);
    o.min_frames = p.value("min_frames", o.min_frames);
    o.blend_seconds = p.value("blend_seconds", o.blend_seconds);
    o.lower_pelvis = p.value("lower_pelvis", o.lower_pelvis);
  } catch (const nlohmann::json::exception& e) {
    return InvalidArgument(origin + ": " + e.what());
  }
  if (!(o.contact_height > 0)) return InvalidArgument(origin + ".contact_height: must be > 0 m");
  if (!(o.max_speed > 0)) return InvalidArgument(origin + ".max_speed: must be > 0 m/s");
  if (o.min_frames < 1) return InvalidArgument(origin + ".min_frames: must be >= 1");
  if (!(o.blend_seconds >= 0)) return InvalidArgument(origin + ".blend_seconds: must be >= 0");
  if (!(o.lower_pelvis >= 0 && o.lower_pelvis <= 0.5))
    return InvalidArgument(origin + ".lower_pelvis: must be in [0, 0.5] m");
  return o;
}

void FootLockReport::Add(const FootLockReport& other) {
  held += other.held;
  runs += other.runs;
  unreached += other.unreached;
  shift += other.shift;
  max_reach_error = std::max(max_reach_error, other.max_reach_error);
  max_lowered = std::max(max_lowered, other.max_lowered);
}

Motion LockFeet(const Skeleton& skeleton, const Motion& motion, const FootLockOptions& options,
                FootLockReport* report, const std::vector<uint8_t>* contacts) {
  Motion out = motion;
  const int64_t frames = motion.num_frames();
  if (contacts && static_cast<int64_t>(contacts->size()) != frames * 4)
    throw std::invalid_argument("LockFeet: contacts must have 4 entries per frame");
  if (frames < 2) return out;
  const auto& parents = skeleton.parents();
  const std::array<std::array<int, 2>, 2> feet = {skeleton.left_foot_joints(),
                                                  skeleton.right_foot_joints()};
  std::vector<std::array<Mat3, kNumJoints>> global(static_cast<size_t>(frames));
  std::vector<std::array<Vec3, kNumJoints>> position(static_cast<size_t>(frames));
  std::array<Mat3, kNumJoints> local{};
  for (int64_t f = 0; f < frames; ++f) {
    for (int joint = 0; joint < kNumJoints; ++joint)
      local[static_cast<size_t>(joint)] = motion.LocalRotation(f, joint);
    ForwardKinematicsFrame(skeleton, local.data(), motion.Translation(f),
                           global[static_cast<size_t>(f)].data(),
                           position[static_cast<size_t>(f)].data());
  }
  FootLockReport counts;
  // Each side's holds: [side][0] the ankle's, [side][1] the toe's.
  std::array<std::array<Hold, 2>, 2> holds;
  for (size_t side = 0; side < feet.size(); ++side) {
    for (int k = 0; k < 2; ++k) {
      const int joint = feet[side][static_cast<size_t>(k)];
      std::vector<Vec3> path(static_cast<size_t>(frames));
      for (int64_t f = 0; f < frames; ++f)
        path[static_cast<size_t>(f)] = position[static_cast<size_t>(f)][static_cast<size_t>(joint)];
      std::vector<char> given;
      if (contacts) {
        given.resize(static_cast<size_t>(frames));
        for (int64_t f = 0; f < frames; ++f)
          given[static_cast<size_t>(f)] =
              (*contacts)[static_cast<size_t>(f * 4) + side * 2 + static_cast<size_t>(k)] != 0;
      }
      holds[side][static_cast<size_t>(k)] =
          FindHold(path, motion.fps, options, contacts ? &given : nullptr, &counts);
    }
  }
  // The ankle's goal at a frame, in the world: its place, by its hold's weight; where it is not
  // fully held and the toe is (the heel lifts, the foot pivots on its toe), the toe's hold carries
  // the ankle along, the foot keeping its world orientation, so that the toe stands at its place.
  const auto ankle_goal = [&](size_t side, int64_t f) {
    const auto& P = position[static_cast<size_t>(f)];
    const Vec3 A = P[static_cast<size_t>(feet[side][0])], T = P[static_cast<size_t>(feet[side][1])];
    const double w_ankle = holds[side][0].weight[static_cast<size_t>(f)];
    Vec3 goal = Goal(holds[side][0], f, A);
    if (holds[side][1].weight[static_cast<size_t>(f)] > 0 && w_ankle < 1)
      goal = goal + (1.0 - w_ankle) * (Goal(holds[side][1], f, T) - T);
    return goal;
  };
  const auto held = [&](size_t side, int64_t f) {
    return holds[side][0].weight[static_cast<size_t>(f)] > 0 ||
           holds[side][1].weight[static_cast<size_t>(f)] > 0;
  };
  // With lower_pelvis, the pelvis comes down (at most that far) where a held foot's goal is out of
  // its leg's reach, by what brings it within reach, smoothly: the drop each frame needs, widened
  // by twice the blend and averaged twice over the blend's width on each side, is at least the
  // need at every frame and has no step. Every foot that is not held keeps its place in the world.
  std::vector<double> lowered(static_cast<size_t>(frames), 0.0);
  if (options.lower_pelvis > 0) {
    std::vector<double> need(static_cast<size_t>(frames), 0.0);
    for (int64_t f = 0; f < frames; ++f) {
      for (size_t side = 0; side < feet.size(); ++side) {
        if (!held(side, f)) continue;
        const auto& P = position[static_cast<size_t>(f)];
        const int ankle = feet[side][0], knee = parents[static_cast<size_t>(ankle)],
                  hip = parents[static_cast<size_t>(knee)];
        const Vec3 H = P[static_cast<size_t>(hip)], K = P[static_cast<size_t>(knee)],
                   A = P[static_cast<size_t>(ankle)];
        const double reach = (Norm(K - H) + Norm(A - K)) * kReachMargin;
        const Vec3 goal = ankle_goal(side, f);
        const double across = std::hypot(goal.x - H.x, goal.y - H.y);
        const double drop = across < reach
                                ? (H.z - goal.z) - std::sqrt(reach * reach - across * across)
                                : options.lower_pelvis;
        need[static_cast<size_t>(f)] =
            std::max(need[static_cast<size_t>(f)], std::clamp(drop, 0.0, options.lower_pelvis));
      }
    }
    lowered =
        SmoothLowering(need, std::max<int64_t>(1, std::lround(options.blend_seconds * motion.fps)));
    for (int64_t f = 0; f < frames; ++f) {
      const double d = lowered[static_cast<size_t>(f)];
      counts.max_lowered = std::max(counts.max_lowered, d);
      if (d <= 0) continue;
      Vec3 t = out.Translation(f);
      t.z -= d;
      out.SetTranslation(f, t);
    }
  }
  for (size_t side = 0; side < feet.size(); ++side) {
    const auto& foot = feet[side];
    const int ankle = foot[0], toe = foot[1];
    const int knee = parents[static_cast<size_t>(ankle)];
    const int hip = parents[static_cast<size_t>(knee)];
    const int pelvis = parents[static_cast<size_t>(hip)];
    for (int64_t f = 0; f < frames; ++f) {
      const double w_ankle = holds[side][0].weight[static_cast<size_t>(f)];
      const double w_toe = holds[side][1].weight[static_cast<size_t>(f)];
      const double down = lowered[static_cast<size_t>(f)];
      if (!held(side, f) && down <= 0) continue;
      const auto& G = global[static_cast<size_t>(f)];
      const auto& P = position[static_cast<size_t>(f)];
      // The leg as it hangs from the (lowered) pelvis; the goals are in the world.
      const Vec3 lower{0, 0, down};
      const Vec3 H = P[static_cast<size_t>(hip)] - lower, K = P[static_cast<size_t>(knee)] - lower,
                 A = P[static_cast<size_t>(ankle)] - lower, T = P[static_cast<size_t>(toe)] - lower;
      const Vec3 wanted_goal = ankle_goal(side, f);
      const Reached leg = ReachAnkle(H, K, A, G[static_cast<size_t>(hip)],
                                     G[static_cast<size_t>(knee)], wanted_goal);
      const Mat3 g_knee = leg.g_hip * leg.knee_local;
      const Vec3 ankle_at = leg.ankle;
      const double missed = Norm(ankle_at - wanted_goal);
      counts.max_reach_error = std::max(counts.max_reach_error, missed);
      if (w_ankle >= 1 && missed > 0.01) ++counts.unreached;
      out.SetLocalRotation(f, hip, Transpose(G[static_cast<size_t>(pelvis)]) * leg.g_hip);
      out.SetLocalRotation(f, knee, leg.knee_local);
      // The foot keeps its world orientation; a held toe turns it to point at the toe's place.
      Mat3 g_ankle = G[static_cast<size_t>(ankle)];
      if (w_toe > 0) {
        const Vec3 to_goal = Goal(holds[side][1], f, P[static_cast<size_t>(toe)]) - ankle_at;
        if (Norm(to_goal) > 1e-6) g_ankle = RotationBetween(T - A, to_goal) * g_ankle;
      }
      out.SetLocalRotation(f, ankle, Transpose(g_knee) * g_ankle);
    }
  }
  if (report) *report = counts;
  return out;
}

}  // namespace motionpipe
