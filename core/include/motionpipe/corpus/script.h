// A clip script: the timeline of actions a procedural clip performs. Base actions (locomotion,
// whole body, legs) follow one another and cover the clip; overlay actions (arms, torso, head)
// run during a base action and are performed jointly with it (see synthesizer.h).
#pragma once

#include <string>
#include <vector>

#include "motionpipe/base/random.h"
#include "motionpipe/corpus/vocabulary.h"

namespace motionpipe::corpus {

struct ActionInstance {
  ActionId id = ActionId::kStand;
  Side side = Side::kNone;
  double start = 0;  // seconds
  double end = 0;
  double speed = 1;      // tempo multiplier
  double amplitude = 1;  // size multiplier
  int reps = 0;
  bool turn_left = true;  // direction of turns, side steps, circles
  double angle = 0;       // radians turned by turn_in_place
  std::string label;      // BABEL-style label of this instance
  std::string caption;    // HumanML3D-style sentence
  bool annotated = true;  // appears in the annotations (a 'stand' under a gesture often does not)

  double duration() const { return end - start; }
  TextParams text_params() const { return {side, speed, amplitude, reps, turn_left}; }
};

// How this performer moves: a real actor never repeats a motion exactly, and no two actors move
// alike. Every clip draws a style; an edited target redraws it with a small jitter.
struct ActorStyle {
  double speed_scale = 1;
  double amplitude_scale = 1;
  double posture_lean = 0;  // radians, + forward
  double arm_swing = 1;
  double stance_width = 0.10;  // metres from the centre line to each foot
  double toe_out = 0.07;       // radians
  double arm_hang_out = 0.04;  // metres
  double sway = 1;             // idle sway amount
  uint64_t noise_seed = 0;     // phases of the smooth idle noise
};

struct ClipScript {
  std::string id;
  double fps = 30;
  double duration = 0;
  double start_x = 0, start_y = 0, start_facing = 0;
  bool start_seated = false;
  std::vector<ActionInstance> base;      // consecutive: base[i].end == base[i+1].start
  std::vector<ActionInstance> overlays;  // each within one base instance
  ActorStyle style;

  int64_t num_frames() const;
  // Index of the base instance running at time t (the last one at or after the end).
  size_t BaseAt(double t) const;
};

struct ScriptOptions {
  double fps = 30;
  double min_seconds = 3;
  double max_seconds = 12;
  double overlay_probability = 0.55;  // per base action
  double second_overlay_probability = 0.15;
  double annotate_stand_probability = 0.5;  // 'stand' under a gesture is labelled this often
};

// A random, physically sensible script (sit down is followed by stand up, overlays only use parts
// the base action leaves free, durations fit the actions' tempo). Deterministic for the rng state.
ClipScript SampleScript(Rng& rng, const ScriptOptions& options, const std::string& id);

// Samples one action instance of `id` with random parameters, texts and a duration; start = 0.
ActionInstance SampleInstance(ActionId id, Rng& rng);
// Duration implied by an action's parameters (repetitions at its tempo), or a sample from its
// range.
double NaturalDuration(const ActionInstance& instance, Rng& rng);
// Rewrites the label and caption for the instance's current parameters.
void RetextInstance(ActionInstance* instance, Rng& rng);

// A verb-first phrase for an instance ("wave with the right hand", "put their hands on their
// hips"), in the second person for instructions ("your") or the third for descriptions ("their").
enum class Person { kSecond, kThird };
std::string VerbPhrase(const ActionInstance& instance, Person person);

// Ground-truth parts of every action in the script at time t (union over active instances).
PartSet PartsAt(const ClipScript& script, double t);

// A new style, and a slightly jittered copy of one (the same actor again).
ActorStyle SampleStyle(Rng& rng);
ActorStyle JitterStyle(const ActorStyle& style, Rng& rng);

}  // namespace motionpipe::corpus
