#include "motionpipe/corpus/edits.h"

#include <algorithm>
#include <cmath>

#include "motionpipe/text/english.h"

namespace motionpipe::corpus {

namespace {

using A = ActionId;

// The bare action ("the wave", "the jump").
std::string Noun(const ActionInstance& a) {
  const std::string verb = VerbPhrase(a, Person::kSecond);
  const size_t space = verb.find(' ');
  return space == std::string::npos ? verb : verb.substr(0, space);
}

std::string Times(int n) {
  static const char* kWords[] = {"zero times", "once",       "twice",    "three times",
                                 "four times", "five times", "six times"};
  return n >= 0 && n <= 6 ? kWords[n] : std::to_string(n) + " times";
}

std::string Fill(std::string text, const std::vector<std::pair<std::string, std::string>>& values) {
  for (const auto& [key, value] : values) {
    size_t at = 0;
    while ((at = text.find(key, at)) != std::string::npos) {
      text.replace(at, key.size(), value);
      at += value.size();
    }
  }
  return text;
}

// Shifts everything after `from` by delta seconds and scales the overlays inside base instance k.
void RetimeBase(ClipScript* s, size_t k, double new_duration) {
  ActionInstance& b = s->base[k];
  const double old_start = b.start, old_end = b.end;
  const double ratio = new_duration / std::max(1e-6, old_end - old_start);
  const double delta = new_duration - (old_end - old_start);
  b.end = b.start + new_duration;
  for (size_t j = k + 1; j < s->base.size(); ++j) {
    s->base[j].start += delta;
    s->base[j].end += delta;
  }
  for (ActionInstance& o : s->overlays) {
    if (o.start >= old_start && o.end <= old_end + 1e-9) {
      o.start = old_start + (o.start - old_start) * ratio;
      o.end = old_start + (o.end - old_start) * ratio;
    } else if (o.start >= old_end - 1e-9) {
      o.start += delta;
      o.end += delta;
    }
  }
  s->duration += delta;
}

// Changes an overlay's duration inside its base, lengthening the base when it would not fit.
void RetimeOverlay(ClipScript* s, size_t index, double new_duration) {
  ActionInstance& o = s->overlays[index];
  const size_t k = s->BaseAt(o.start);
  const double needed = o.start + new_duration + 0.2 - s->base[k].end;
  if (needed > 0) RetimeBase(s, k, s->base[k].duration() + needed);
  s->overlays[index].end = s->overlays[index].start + new_duration;
}

double RepPeriod(const ActionInstance& a) {
  Rng unused(0);
  ActionInstance one = a;
  one.reps = 1;
  ActionInstance two = a;
  two.reps = 2;
  return NaturalDuration(two, unused) - NaturalDuration(one, unused);
}

std::string AmplitudeText(const ActionInstance& a, bool more, Rng& rng) {
  const ActionKind kind = Def(a.id).kind;
  const std::string side = a.side == Side::kLeft ? "left" : "right";
  std::vector<std::string> options;
  if (kind == ActionKind::kArm) {
    options =
        more ? std::vector<std::string>{"raise your {side} arm higher",
                                        "{verb} with bigger movements", "lift the hand higher",
                                        "make the arm movement bigger", "extend the arm further"}
             : std::vector<std::string>{
                   "keep your {side} hand lower", "{verb} with smaller movements",
                   "don't raise the arm so high", "make the arm movement smaller"};
    if (a.side == Side::kBoth) {
      options =
          more
              ? std::vector<std::string>{"raise both arms higher", "make the arm movements bigger"}
              : std::vector<std::string>{"keep both hands lower", "make the arm movements smaller"};
    }
  } else if (a.id == A::kKick || a.id == A::kKneeLift || a.id == A::kStomp ||
             a.id == A::kStretchLeg) {
    options = more ? std::vector<std::string>{"kick higher", "lift the {side} leg higher",
                                              "raise the knee higher", "{verb} further"}
                   : std::vector<std::string>{"don't lift the {side} leg so high",
                                              "keep the foot lower", "{verb} less"};
    if (a.id == A::kKick) options.push_back(more ? "kick higher and further" : "kick lower");
  } else if (a.id == A::kJump || a.id == A::kHop) {
    options =
        more ? std::vector<std::string>{"jump higher", "jump further", "make bigger jumps"}
             : std::vector<std::string>{"jump lower", "make smaller jumps", "don't jump so high"};
  } else if (kind == ActionKind::kHead) {
    options = more ? std::vector<std::string>{"move your head more", "{verb} more clearly",
                                              "make the head movement bigger"}
                   : std::vector<std::string>{"move your head less", "only {verb} slightly",
                                              "make the head movement smaller"};
  } else {
    options = more ? std::vector<std::string>{"bend down more", "go lower", "bend further",
                                              "{verb} more", "{verb} deeper"}
                   : std::vector<std::string>{"don't bend so much", "bend less", "stay higher",
                                              "only {verb} a little"};
  }
  return Fill(rng.Pick(options), {{"{verb}", VerbPhrase(a, Person::kSecond)}, {"{side}", side}});
}

struct Candidate {
  EditKind kind;
  bool overlay;  // the edit targets overlays[index] (else base[index])
  size_t index;
};

// Every edit that applies to this script.
std::vector<Candidate> Candidates(const ClipScript& source) {
  std::vector<Candidate> candidates;
  for (size_t k = 0; k < source.base.size(); ++k) {
    const ActionInstance& b = source.base[k];
    if (SpeedMatters(b.id)) candidates.push_back({EditKind::kSpeed, false, k});
    if (AmplitudeMatters(b.id)) candidates.push_back({EditKind::kAmplitude, false, k});
    if (Def(b.id).sided || b.id == A::kTurnInPlace || b.id == A::kSideStep ||
        b.id == A::kWalkCircle) {
      candidates.push_back({EditKind::kSide, false, k});
    }
    if (b.reps > 0) candidates.push_back({EditKind::kRepetitions, false, k});
    if (b.id != A::kSitDown && b.id != A::kStandUp && b.id != A::kJumpingJacks &&
        b.duration() > 1.8) {
      candidates.push_back({EditKind::kAddAction, false, k});
    }
    if (IsBaseKind(Def(b.id).kind) && b.id != A::kSitDown && b.id != A::kStandUp) {
      candidates.push_back({EditKind::kReplaceBase, false, k});
    }
  }
  for (size_t k = 0; k < source.overlays.size(); ++k) {
    const ActionInstance& o = source.overlays[k];
    candidates.push_back({EditKind::kRemoveAction, true, k});
    candidates.push_back({EditKind::kReplaceAction, true, k});
    if (SpeedMatters(o.id)) candidates.push_back({EditKind::kSpeed, true, k});
    if (AmplitudeMatters(o.id)) candidates.push_back({EditKind::kAmplitude, true, k});
    if (Def(o.id).sided && o.side != Side::kBoth) candidates.push_back({EditKind::kSide, true, k});
    if (o.reps > 0) candidates.push_back({EditKind::kRepetitions, true, k});
  }
  const bool sit_pair =
      source.base.size() >= 2 && source.base[source.base.size() - 2].id == A::kSitDown;
  if (source.base.size() >= 2 && !sit_pair && source.base.back().id != A::kStandUp) {
    candidates.push_back({EditKind::kTiming, false, source.base.size() - 1});
  }
  candidates.push_back({EditKind::kPosture, false, 0});
  return candidates;
}

// What an edit of one kind reads and writes: the source, the chosen candidate and its instance
// before the edit, and the edit being built (its target script and the target's instance).
struct EditContext {
  const ClipScript& source;
  const Candidate& pick;
  const ActionInstance& original;
  const std::string& verb;  // the original's verb phrase, second person
  ClipScript& t;            // edit.target
  ActionInstance& inst;     // the picked instance in t
  Edit& edit;
  Rng& rng;
};

// The text of an edit that replaces the original action (an overlay or a base action).
std::string ReplacementText(const EditContext& in, const ActionInstance& replacement) {
  return Fill(in.rng.Pick(std::vector<std::string>{"{new} instead of {old_ing}",
                                                   "instead of {old_ing}, {new}", "{new} instead",
                                                   "don't {old}, {new}"}),
              {{"{new}", VerbPhrase(replacement, Person::kSecond)},
               {"{old}", in.verb},
               {"{old_ing}", text::GerundPhrase(in.verb)}});
}

void ApplySpeed(const EditContext& in) {
  const bool faster =
      in.original.speed < 1.25 && (in.original.speed < 0.8 || in.rng.Bernoulli(0.5));
  const double factor = faster ? in.rng.Uniform(1.35, 1.6) : in.rng.Uniform(0.6, 0.72);
  in.inst.speed = in.original.speed * factor;
  const ActionKind kind = Def(in.inst.id).kind;
  const bool continuous =
      kind == ActionKind::kLocomotion && in.inst.reps == 0 && in.inst.id != A::kTurnInPlace;
  if (!continuous) {
    const double new_duration =
        std::max(0.8, in.original.duration() / (in.inst.reps > 0 ? factor : std::sqrt(factor)));
    if (in.pick.overlay)
      RetimeOverlay(&in.t, in.pick.index, new_duration);
    else
      RetimeBase(&in.t, in.pick.index, new_duration);
  }
  const std::string word = faster ? "faster" : "slower";
  in.edit.text = Fill(in.rng.Pick(std::vector<std::string>{
                          "{verb} {word}", "do it {word}", "move {word}", "{verb} a bit {word}",
                          faster ? "speed up" : "slow down", "{verb}, but {word}"}),
                      {{"{verb}", in.verb}, {"{word}", word}, {"{noun}", Noun(in.original)}});
}

void ApplyAmplitude(const EditContext& in) {
  const bool more =
      in.original.amplitude < 1.15 && (in.original.amplitude < 0.8 || in.rng.Bernoulli(0.5));
  in.inst.amplitude =
      in.original.amplitude * (more ? in.rng.Uniform(1.4, 1.7) : in.rng.Uniform(0.45, 0.6));
  in.edit.text = AmplitudeText(in.original, more, in.rng);
}

void ApplySide(const EditContext& in) {
  if (Def(in.inst.id).sided) {
    in.inst.side = in.original.side == Side::kLeft ? Side::kRight : Side::kLeft;
    const std::string other = in.inst.side == Side::kLeft ? "left" : "right";
    const bool leg = Def(in.inst.id).kind == ActionKind::kLeg || in.inst.id == A::kHop ||
                     in.inst.id == A::kKneel;
    const std::string limb =
        leg ? "leg" : (Def(in.inst.id).kind == ActionKind::kArm ? "hand" : "side");
    in.edit.text = Fill(in.rng.Pick(std::vector<std::string>{
                            "use your {other} {limb} instead", "do it with the other {limb}",
                            "use the {other} {limb} instead of the {side} one",
                            "switch to the {other} {limb}", "{new_verb} instead"}),
                        {{"{other}", other},
                         {"{limb}", limb},
                         {"{side}", in.original.side == Side::kLeft ? "left" : "right"},
                         {"{new_verb}", VerbPhrase(in.inst, Person::kSecond)}});
  } else {
    in.inst.turn_left = !in.original.turn_left;
    in.inst.angle = -in.original.angle;
    const std::string other = in.inst.turn_left ? "left" : "right";
    in.edit.text = Fill(in.rng.Pick(std::vector<std::string>{
                            "{new_verb} instead", "go {other} instead",
                            "to the {other} instead of the {old}", "{new_verb}, not {old}"}),
                        {{"{new_verb}", VerbPhrase(in.inst, Person::kSecond)},
                         {"{other}", other},
                         {"{old}", in.original.turn_left ? "left" : "right"}});
  }
}

void ApplyRepetitions(const EditContext& in) {
  const ActionDef& def = Def(in.inst.id);
  int reps = in.original.reps;
  while (reps == in.original.reps)
    reps = in.rng.Int(std::max(1, def.min_reps - 1), def.max_reps + 1);
  in.inst.reps = reps;
  const double new_duration =
      std::max(0.8, in.original.duration() + (reps - in.original.reps) * RepPeriod(in.original));
  if (in.pick.overlay)
    RetimeOverlay(&in.t, in.pick.index, new_duration);
  else
    RetimeBase(&in.t, in.pick.index, new_duration);
  std::vector<std::string> options = {"do it {times}", "{verb} {times}", "repeat it {times}"};
  if (reps == 1) options = {"{verb} only once", "just once"};
  if (reps == 1 && in.verb.find(' ') == std::string::npos) options.push_back("do only one {noun}");
  if (reps == in.original.reps + 1) options.push_back("one more time");
  if (reps < in.original.reps) options.push_back("fewer repetitions, only {times}");
  in.edit.text =
      Fill(in.rng.Pick(options),
           {{"{verb}", in.verb}, {"{times}", Times(reps)}, {"{noun}", Noun(in.original)}});
}

void ApplyAddAction(const EditContext& in) {
  // A new gesture during this base action, on parts it leaves free.
  const ActionInstance& base = in.source.base[in.pick.index];
  PartSet used = PartsOf(base.id, base.side);
  for (const ActionInstance& o : in.source.overlays) {
    if (o.start < base.end && o.end > base.start) used |= PartsOf(o.id, o.side);
  }
  ActionInstance added;
  bool found = false;
  for (int attempt = 0; attempt < 30 && !found; ++attempt) {
    const ActionId id =
        static_cast<ActionId>(in.rng.Int(static_cast<int>(A::kWave), static_cast<int>(A::kLookUp)));
    added = SampleInstance(id, in.rng);
    found = (PartsOf(added.id, added.side) & used) == 0 &&
            (Def(id).kind != ActionKind::kTorso || base.id == A::kStand || base.id == A::kWalk);
  }
  if (!found) {  // nothing fits: fall back to a posture edit
    in.edit.kind = EditKind::kPosture;
    in.t.style.posture_lean = in.source.style.posture_lean - 0.12;
    in.edit.text = "stand up straighter";
    in.edit.edit_start = 0;
    in.edit.edit_end = in.source.duration;
    return;
  }
  const double room = base.duration() - 0.4;
  const double length = std::min(added.duration(), room);
  added.start = base.start + 0.2 + in.rng.Uniform(0, room - length);
  added.end = added.start + length;
  in.t.overlays.push_back(added);
  in.edit.edit_start = added.start;
  in.edit.edit_end = added.end;
  const bool at_end = added.end > base.end - 0.6;
  std::vector<std::string> options = {"also {new}", "{new} while {base_ing}",
                                      "{new} at the same time", "while {base_ing}, {new}",
                                      "add: {new}"};
  if (at_end) options.push_back("{new} at the end");
  in.edit.text = Fill(in.rng.Pick(options),
                      {{"{new}", VerbPhrase(added, Person::kSecond)},
                       {"{base_ing}", text::GerundPhrase(VerbPhrase(base, Person::kSecond))}});
}

void ApplyRemoveAction(const EditContext& in) {
  in.t.overlays.erase(in.t.overlays.begin() + static_cast<std::ptrdiff_t>(in.pick.index));
  std::vector<std::string> options = {"don't {verb}", "do not {verb}", "skip {verb_ing}",
                                      "without {verb_ing}", "just {base}, without {verb_ing}"};
  if (Def(in.original.id).kind == ActionKind::kArm) options.push_back("keep your arms down");
  if (Def(in.original.id).kind == ActionKind::kHead) options.push_back("keep your head still");
  in.edit.text = Fill(in.rng.Pick(options),
                      {{"{verb}", in.verb},
                       {"{noun}", Noun(in.original)},
                       {"{verb_ing}", text::GerundPhrase(in.verb)},
                       {"{base}", VerbPhrase(in.source.base[in.source.BaseAt(in.original.start)],
                                             Person::kSecond)}});
}

void ApplyReplaceAction(const EditContext& in) {
  const ActionInstance& base = in.source.base[in.source.BaseAt(in.original.start)];
  PartSet used = PartsOf(base.id, base.side);
  for (size_t k = 0; k < in.source.overlays.size(); ++k) {
    const ActionInstance& o = in.source.overlays[k];
    if (k != in.pick.index && o.start < in.original.end && o.end > in.original.start)
      used |= PartsOf(o.id, o.side);
  }
  ActionInstance replacement;
  bool found = false;
  for (int attempt = 0; attempt < 30 && !found; ++attempt) {
    const ActionId id =
        static_cast<ActionId>(in.rng.Int(static_cast<int>(A::kWave), static_cast<int>(A::kLookUp)));
    replacement = SampleInstance(id, in.rng);
    found = id != in.original.id && (PartsOf(id, replacement.side) & used) == 0 &&
            Def(id).kind != ActionKind::kTorso;
  }
  if (!found) {
    in.t.overlays.erase(in.t.overlays.begin() + static_cast<std::ptrdiff_t>(in.pick.index));
    in.edit.kind = EditKind::kRemoveAction;
    in.edit.text = "don't " + in.verb;
    return;
  }
  replacement.start = in.original.start;
  replacement.end = in.original.end;
  in.inst = replacement;
  in.edit.text = ReplacementText(in, replacement);
}

void ApplyTiming(const EditContext& in) {
  // Do not perform the last base action: keep doing the previous one instead.
  const size_t last = in.t.base.size() - 1;
  const ActionInstance removed = in.t.base[last];
  const ActionInstance& previous = in.source.base[last - 1];
  in.edit.edit_start = removed.start;
  in.edit.edit_end = in.source.duration;
  in.t.base.pop_back();
  in.t.base.back().end = removed.end;
  in.t.overlays.erase(
      std::remove_if(in.t.overlays.begin(), in.t.overlays.end(),
                     [&](const ActionInstance& o) { return o.start >= removed.start - 1e-9; }),
      in.t.overlays.end());
  RetextInstance(&in.t.base.back(), in.rng);
  in.edit.text = Fill(in.rng.Pick(std::vector<std::string>{
                          "do not {last} at the end, keep {prev_ing}", "don't {last} at the end",
                          "keep {prev_ing} instead of {last_ing}", "skip {last_ing} at the end",
                          "don't {last} at the end, just keep {prev_ing}"}),
                      {{"{last}", VerbPhrase(removed, Person::kSecond)},
                       {"{prev_ing}", text::GerundPhrase(VerbPhrase(previous, Person::kSecond))},
                       {"{last_ing}", text::GerundPhrase(VerbPhrase(removed, Person::kSecond))},
                       {"{last_noun}", Noun(removed)}});
}

void ApplyReplaceBase(const EditContext& in) {
  const ActionKind kind = Def(in.original.id).kind;
  ActionInstance replacement;
  for (int attempt = 0; attempt < 30; ++attempt) {
    const ActionId id = static_cast<ActionId>(
        in.rng.Int(static_cast<int>(A::kStand), static_cast<int>(A::kStretchLeg)));
    if (id == in.original.id || id == A::kSitDown || id == A::kStandUp) continue;
    if (Def(id).kind != kind &&
        !(kind == ActionKind::kLeg && Def(id).kind == ActionKind::kWholeBody))
      continue;
    replacement = SampleInstance(id, in.rng);
    break;
  }
  if (replacement.id == A::kStand && in.original.id == A::kStand)
    replacement = SampleInstance(A::kWalk, in.rng);
  // Overlays that would clash with the new action's parts are dropped.
  const PartSet parts = PartsOf(replacement.id, replacement.side);
  in.t.overlays.erase(std::remove_if(in.t.overlays.begin(), in.t.overlays.end(),
                                     [&](const ActionInstance& o) {
                                       return o.start >= in.original.start &&
                                              o.end <= in.original.end + 1e-9 &&
                                              (PartsOf(o.id, o.side) & parts) != 0;
                                     }),
                      in.t.overlays.end());
  replacement.start = in.original.start;
  replacement.end = in.original.end;
  in.inst = replacement;
  RetimeBase(&in.t, in.pick.index,
             std::max(in.original.duration(),
                      std::min(replacement.duration(), in.original.duration() * 1.5)));
  in.edit.text = ReplacementText(in, replacement);
}

void ApplyPosture(const EditContext& in) {
  const bool straighter = in.source.style.posture_lean > -0.02;
  in.t.style.posture_lean = in.source.style.posture_lean + (straighter ? -0.12 : 0.15);
  in.edit.text = in.rng.Pick(
      straighter ? std::vector<std::string>{"stand up straighter", "keep your back straight",
                                            "stand a little straighter", "lean back a bit"}
                 : std::vector<std::string>{"lean forward more", "hunch over a little",
                                            "bend your upper body forward a bit", "lean forward"});
  in.edit.edit_start = 0;
  in.edit.edit_end = in.source.duration;
}

void ApplyEdit(const EditContext& in) {
  switch (in.pick.kind) {
    case EditKind::kSpeed:
      ApplySpeed(in);
      break;
    case EditKind::kAmplitude:
      ApplyAmplitude(in);
      break;
    case EditKind::kSide:
      ApplySide(in);
      break;
    case EditKind::kRepetitions:
      ApplyRepetitions(in);
      break;
    case EditKind::kAddAction:
      ApplyAddAction(in);
      break;
    case EditKind::kRemoveAction:
      ApplyRemoveAction(in);
      break;
    case EditKind::kReplaceAction:
      ApplyReplaceAction(in);
      break;
    case EditKind::kTiming:
      ApplyTiming(in);
      break;
    case EditKind::kReplaceBase:
      ApplyReplaceBase(in);
      break;
    case EditKind::kPosture:
      ApplyPosture(in);
      break;
    case EditKind::kCount:
      break;
  }
}

}  // namespace

const char* EditKindName(EditKind kind) {
  switch (kind) {
    case EditKind::kSpeed:
      return "speed";
    case EditKind::kAmplitude:
      return "amplitude";
    case EditKind::kSide:
      return "side";
    case EditKind::kAddAction:
      return "add_action";
    case EditKind::kRemoveAction:
      return "remove_action";
    case EditKind::kReplaceAction:
      return "replace_action";
    case EditKind::kRepetitions:
      return "repetitions";
    case EditKind::kTiming:
      return "timing";
    case EditKind::kReplaceBase:
      return "replace_base";
    case EditKind::kPosture:
      return "posture";
    case EditKind::kCount:
      break;
  }
  return "unknown";
}

Result<EditKindSet> ParseEditKinds(const std::vector<std::string>& names) {
  if (names.empty()) return kEveryEditKind;
  EditKindSet set = 0;
  for (const std::string& name : names) {
    bool found = false;
    std::string known;
    for (int k = 0; k < static_cast<int>(EditKind::kCount); ++k) {
      const char* kind_name = EditKindName(static_cast<EditKind>(k));
      known += std::string(known.empty() ? "" : ", ") + kind_name;
      if (name == kind_name) set |= 1u << k, found = true;
    }
    if (!found) return InvalidArgument("unknown edit kind '" + name + "' (known: " + known + ")");
  }
  return set;
}

std::vector<std::string> EditKindNames(EditKindSet kinds) {
  std::vector<std::string> names;
  for (int k = 0; k < static_cast<int>(EditKind::kCount); ++k) {
    if (Contains(kinds, static_cast<EditKind>(k)))
      names.emplace_back(EditKindName(static_cast<EditKind>(k)));
  }
  return names;
}

std::optional<Edit> SampleEdit(const ClipScript& source, Rng& rng, EditKindSet kinds) {
  // Every edit that applies to this script, then one of them at random.
  const std::vector<Candidate> candidates = Candidates(source);
  // Choose the kind of edit first (so that kinds with many candidate actions do not dominate), then
  // the action it applies to.
  static const double kKindWeight[] = {1.0, 1.2, 1.0, 1.2, 1.0, 0.8, 0.8, 0.6, 0.8, 0.4};
  std::vector<double> weights(static_cast<size_t>(EditKind::kCount), 0.0);
  bool any = false;
  for (const Candidate& c : candidates) {
    if (!Contains(kinds, c.kind)) continue;
    weights[static_cast<size_t>(c.kind)] = kKindWeight[static_cast<size_t>(c.kind)];
    any = true;
  }
  if (!any) return std::nullopt;
  const auto chosen = static_cast<EditKind>(rng.Weighted(weights));
  std::vector<Candidate> of_kind;
  for (const Candidate& c : candidates) {
    if (c.kind == chosen) of_kind.push_back(c);
  }
  const Candidate pick = rng.Pick(of_kind);
  Edit edit;
  edit.kind = pick.kind;
  edit.target = source;
  edit.target.style = JitterStyle(source.style, rng);
  ClipScript& t = edit.target;
  ActionInstance& inst = pick.overlay ? t.overlays[pick.index] : t.base[pick.index];
  const ActionInstance original =
      pick.overlay ? source.overlays[pick.index] : source.base[pick.index];
  edit.edit_start = original.start;
  edit.edit_end = original.end;
  const std::string verb = VerbPhrase(original, Person::kSecond);

  ApplyEdit({source, pick, original, verb, t, inst, edit, rng});
  // The edited instance gets texts for its new parameters (it no longer exists after a removal, and
  // a fallback may have changed the kind, so decide on the final kind).
  if (edit.kind == EditKind::kSpeed || edit.kind == EditKind::kAmplitude ||
      edit.kind == EditKind::kSide || edit.kind == EditKind::kRepetitions ||
      edit.kind == EditKind::kReplaceAction || edit.kind == EditKind::kReplaceBase) {
    RetextInstance(&inst, rng);
  }
  t.duration = t.base.back().end;
  if (!Contains(kinds, edit.kind)) return std::nullopt;
  return edit;
}

}  // namespace motionpipe::corpus
