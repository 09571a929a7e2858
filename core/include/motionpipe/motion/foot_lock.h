// Foot locking: a post-process that plants a motion's feet where it already puts them on the floor.
// Each foot joint (ankle, toe) that stays below a contact height and slower than a speed for a run
// of frames is held at one horizontal place over that run (the run's mean), and the leg reaches it
// by two-bone IK: the knee folds in its own bending plane, the hip swings by the smallest rotation,
// the ankle keeps the foot's world orientation (turned, where the toe is held too, to point at the
// toe's place); a toe held while its ankle is not (the heel lifts, the foot pivots on its toe)
// carries the ankle along, the foot's orientation kept, so that the toe stands at its place. Where
// a place is out of the leg's reach the pelvis comes down (smoothly, at most `lower_pelvis`; the
// feet not held keep their places in the world), and what is still out of reach is approached
// horizontally, at the joint's own height, so that a foot that cannot reach it slides rather than
// floats. Only the hips', knees' and ankles' local rotations and the pelvis's height change; the
// pelvis's path across the floor, its orientation and the upper body's pose are the motion's own.
// What the model generated is the input; this is not the model: the evaluation reports both.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

// How a model's own contact calls (LockFeet's `contacts`) choose the frames to hold.
enum class GivenContacts {
  kAlone,           // the calls replace the height-and-speed test (a call in the air is held)
  kNearFloor,       // the calls where the joint is below the contact height, at any speed
  kNearFloorOrTest  // those, and every frame the height-and-speed test holds
};

struct FootLockOptions {
  double floor = 0;              // z of the floor (joint level), metres
  double contact_height = 0.05;  // a foot joint below floor + this may be in contact (the metric's)
  double max_speed = 1.0;        // m/s: a foot joint faster than this is swinging, not sliding
  int min_frames = 2;            // shortest run of contact frames that is held
  double blend_seconds = 0.1;    // on each side of a run the hold fades in/out over this long
  // m: how far the pelvis may come down, smoothly, where a held foot is out of its leg's reach
  // (0: the pelvis is the motion's own and an unreachable foot slides). 0.1 chosen on validation
  // spans and triplets (docs/EXPERIMENTS.md "A held toe, and a pelvis that comes down").
  double lower_pelvis = 0.1;
  // Only read when LockFeet is given contacts; not one of the map's keys (the caller that has
  // the calls names its own choice: the MDT's edit option foot_lock.contacts).
  GivenContacts given = GivenContacts::kAlone;
};

struct FootLockReport {
  int64_t held = 0;            // foot-joint frames held at a run's place
  int64_t runs = 0;            // contact runs held
  int64_t unreached = 0;       // held ankle frames the leg could not reach (> 1 cm short)
  double shift = 0;            // m: horizontal distances the held joints were moved, summed
  double max_reach_error = 0;  // m: the largest distance an ankle stayed from its goal
  double max_lowered = 0;      // m: the most the pelvis came down (options.lower_pelvis)

  // Another motion's counts added to these (a stage's total over its motions).
  void Add(const FootLockReport& other);
  // m: the mean horizontal distance a held joint was moved (0 when none was held).
  double MeanShift() const { return held > 0 ? shift / static_cast<double>(held) : 0.0; }
};

// The options as a map, the keys FootLockOptionsFromJson reads (their one list).
nlohmann::json FootLockOptionsToJson(const FootLockOptions& options);

// The options from a map (contact_height, max_speed, min_frames, blend_seconds, lower_pelvis;
// missing keys keep their defaults; `other_keys` are the caller's own and skipped); InvalidArgument
// naming `origin` and the key when a value is of the wrong type or out of range, or a key is
// unknown (a misspelt option must not pass for the default).
Result<FootLockOptions> FootLockOptionsFromJson(const nlohmann::json& params,
                                                const std::string& origin,
                                                const std::vector<std::string>& other_keys = {});

// The motion with its feet held (frames, fps, translation and every other joint unchanged).
// `report` (optional) receives the counts above. `contacts` (optional, [frames * 4]: per frame the
// left ankle, left toe, right ankle and right toe, non-zero where that joint stands) replaces the
// contact-height and speed test: a model that predicts its own contacts (the MDT's contact head)
// says which frames to hold, alone or with the test as options.given says; min_frames and the
// blend still apply. std::invalid_argument when its size is not 4 per frame.
Motion LockFeet(const Skeleton& skeleton, const Motion& motion, const FootLockOptions& options = {},
                FootLockReport* report = nullptr, const std::vector<uint8_t>* contacts = nullptr);

}  // namespace motionpipe
