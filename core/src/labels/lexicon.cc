// The offline lexicon labeler (labeler.h). Written from the body-part conventions of SINC's GPT-3
// answers on the training split of data/text/babel_action_labels_gpt3.json: locomotion moves the
// legs and the global orientation, looking and turning the torso, gestures both arms unless a side
// is named, objects of the hands (face, chest, head) add the torso.
#include <algorithm>
#include <cctype>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "motionpipe/labels/labeler.h"

namespace motionpipe::labels {

namespace {

constexpr PartSet G = PartBit(BodyPart::kGlobal), T = PartBit(BodyPart::kTorso),
                  LA = PartBit(BodyPart::kLeftArm), RA = PartBit(BodyPart::kRightArm),
                  LL = PartBit(BodyPart::kLeftLeg), RL = PartBit(BodyPart::kRightLeg);
constexpr PartSet kArms = LA | RA, kLegs = LL | RL;

enum class Limb { kNone, kArm, kLeg };

struct Noun {
  Limb limb = Limb::kNone;
  PartSet parts = 0;  // for non-limb nouns (torso, global) or extra parts
  bool plural = false;
};

const std::unordered_map<std::string, Noun>& Nouns() {
  static const std::unordered_map<std::string, Noun> nouns = {
      // arms (GPT maps hands, wrists, shoulders to the arm)
      {"arm", {Limb::kArm, 0, false}},
      {"arms", {Limb::kArm, 0, true}},
      {"hand", {Limb::kArm, 0, false}},
      {"hands", {Limb::kArm, 0, true}},
      {"elbow", {Limb::kArm, 0, false}},
      {"elbows", {Limb::kArm, 0, true}},
      {"wrist", {Limb::kArm, 0, false}},
      {"wrists", {Limb::kArm, 0, true}},
      {"finger", {Limb::kArm, 0, false}},
      {"fingers", {Limb::kArm, 0, false}},
      {"fist", {Limb::kArm, 0, false}},
      {"fists", {Limb::kArm, 0, true}},
      {"palm", {Limb::kArm, 0, false}},
      {"palms", {Limb::kArm, 0, true}},
      {"forearm", {Limb::kArm, 0, false}},
      {"forearms", {Limb::kArm, 0, true}},
      {"shoulder", {Limb::kArm, 0, false}},
      {"shoulders", {Limb::kArm, T, true}},
      {"thumb", {Limb::kArm, 0, false}},
      {"biceps", {Limb::kArm, 0, false}},
      // legs
      {"leg", {Limb::kLeg, 0, false}},
      {"legs", {Limb::kLeg, 0, true}},
      {"foot", {Limb::kLeg, 0, false}},
      {"feet", {Limb::kLeg, 0, true}},
      {"knee", {Limb::kLeg, 0, false}},
      {"knees", {Limb::kLeg, 0, true}},
      {"ankle", {Limb::kLeg, 0, false}},
      {"ankles", {Limb::kLeg, 0, true}},
      {"toe", {Limb::kLeg, 0, false}},
      {"toes", {Limb::kLeg, 0, true}},
      {"heel", {Limb::kLeg, 0, false}},
      {"heels", {Limb::kLeg, 0, true}},
      {"thigh", {Limb::kLeg, 0, false}},
      {"thighs", {Limb::kLeg, 0, true}},
      {"shin", {Limb::kLeg, 0, false}},
      // torso (neck and head belong to it)
      {"head", {Limb::kNone, T, false}},
      {"neck", {Limb::kNone, T, false}},
      {"chest", {Limb::kNone, T, false}},
      {"torso", {Limb::kNone, T, false}},
      {"spine", {Limb::kNone, T, false}},
      {"trunk", {Limb::kNone, T, false}},
      {"face", {Limb::kNone, T, false}},
      {"chin", {Limb::kNone, T, false}},
      {"mouth", {Limb::kNone, T, false}},
      {"nose", {Limb::kNone, T, false}},
      {"ear", {Limb::kNone, T, false}},
      {"ears", {Limb::kNone, T, false}},
      {"eyes", {Limb::kNone, T, false}},
      {"forehead", {Limb::kNone, T, false}},
      {"stomach", {Limb::kNone, T, false}},
      {"belly", {Limb::kNone, T, false}},
      {"abdomen", {Limb::kNone, T, false}},
      {"lips", {Limb::kNone, T, false}},
      // global orientation
      {"hips", {Limb::kNone, G, false}},
      {"hip", {Limb::kNone, G, false}},
      {"waist", {Limb::kNone, G, false}},
      {"pelvis", {Limb::kNone, G, false}},
      {"butt", {Limb::kNone, G, false}},
      {"buttocks", {Limb::kNone, G, false}},
  };
  return nouns;
}

// Verbs (base form, gerund and third person are normalised to it) with their usual parts.
const std::unordered_map<std::string, PartSet>& Verbs() {
  static const std::unordered_map<std::string, PartSet> verbs = [] {
    std::unordered_map<std::string, PartSet> v;
    auto add = [&](std::initializer_list<const char*> words, PartSet parts) {
      for (const char* w : words) v.emplace(w, parts);  // the first list that names a verb decides
    };
    // locomotion and whole-body support: legs and the global orientation
    add({"walk",       "run",      "jog",      "jump",    "hop",     "skip",     "step",
         "stand",      "sit",      "squat",    "kneel",   "crouch",  "lie",      "crawl",
         "climb",      "march",    "stomp",    "sprint",  "shuffle", "gallop",   "tiptoe",
         "lunge",      "stumble",  "fall",     "trip",    "balance", "pace",     "stroll",
         "wander",     "go",       "strut",    "limp",    "leap",    "ascend",   "descend",
         "land",       "stagger",  "sidestep", "waddle",  "skate",   "ski",      "rise",
         "get",        "travel",   "proceed",  "move",    "moving",  "backstep", "cartwheel",
         "somersault", "flip",     "roll",     "lay",     "slide",   "glide",    "dodge",
         "duck",       "swim",     "stance",   "hurdle",  "jumping", "jumps",    "steps",
         "stairs",     "squats",   "lunges",   "sits",    "stands",  "kneels",   "backpedal",
         "pedal",      "approach", "retreat",  "advance", "walkway", "jog",      "mount",
         "dismount",   "ride"},
        G | kLegs);
    // legs only
    add({"kick", "knee", "stretch_leg"}, kLegs);
    // torso: looking, turning, bending at the waist
    add({"look",   "nod",    "turn",    "rotate", "twist",  "glance", "gaze",  "stare",
         "watch",  "peek",   "listen",  "face",   "shrug",  "bow",    "tilt",  "sway",
         "wiggle", "shiver", "breathe", "cough",  "sneeze", "yawn",   "laugh", "cry"},
        T);
    add({"lean", "bend", "arch", "hunch", "slouch", "straighten", "recline", "curl", "sway",
         "rock"},
        G | T);
    add({"spin", "pivot"}, G | T | kLegs);
    add({"dance", "exercise", "celebrate", "wrestle", "yoga"}, G | T | kArms | kLegs);
    add({"act", "mime", "pretend", "imitate", "mimic", "zombie", "box"}, T | kArms);
    // the arms with the torso behind them: striking, reaching, pushing
    add({"throw",    "punch",   "reach",    "push",    "pull",  "stretch",   "play",
         "answer",   "adjust",  "aim",      "attack",  "argue", "fight",     "strike",
         "hit",      "jab",     "uppercut", "hook",    "block", "parry",     "swat",
         "slap",     "chop",    "dig",      "sweep",   "mop",   "saw",       "hammer",
         "row",      "paddle",  "shoot",    "conduct", "drum",  "shovel",    "operate",
         "assemble", "arrange", "beat",     "beckon",  "swim",  "backstroke"},
        T | kArms);
    // the arms: gestures, reaching, handling objects
    add({"wave",    "throw",  "catch",   "grab",   "pick",    "hold",    "carry",   "reach",
         "point",   "punch",  "clap",    "lift",   "raise",   "push",    "pull",    "touch",
         "scratch", "wipe",   "drink",   "eat",    "salute",  "put",     "place",   "give",
         "swing",   "flap",   "open",    "close",  "pour",    "brush",   "comb",    "type",
         "write",   "draw",   "slap",    "shake",  "rub",     "tap",     "grip",    "grasp",
         "toss",    "pass",   "drop",    "fold",   "cross",   "extend",  "spread",  "stretch",
         "gesture", "signal", "beckon",  "hug",    "embrace", "applaud", "conduct", "stir",
         "cut",     "knock",  "paint",   "clean",  "adjust",  "fix",     "juggle",  "dribble",
         "shoot",   "aim",    "row",     "paddle", "pat",     "poke",    "pinch",   "squeeze",
         "press",   "wring",  "unscrew", "screw",  "cheer",   "flail",   "flex",    "circle",
         "lower",   "bring",  "use",     "hold",   "set",     "grab",    "check",   "answer",
         "call",    "sign",   "feed",    "dress",  "wash",    "shave",   "blow",    "smell",
         "sip",     "bite",   "swat",    "fan",    "block",   "parry",   "jab",     "uppercut",
         "hook",    "elbow",  "chop",    "swipe",  "scoop",   "stack",   "collect", "gather",
         "remove",  "insert", "attach",  "tie",    "untie",   "button",  "zip",     "catching",
         "throwing"},
        kArms);
    return v;
  }();
  return verbs;
}

// Verbs that act on the body part they name ("bend knees", "move arms", "arms go up"): with a body
// noun next to them they add nothing of their own.
const std::unordered_set<std::string>& GenericVerbs() {
  static const std::unordered_set<std::string> words = {
      "move",   "go",    "bend",   "lift",  "raise", "lower",  "swing", "shake",   "stretch",
      "extend", "cross", "circle", "twist", "flex",  "rotate", "turn",  "tilt",    "wave",
      "put",    "place", "bring",  "hold",  "keep",  "open",   "close", "spread",  "flap",
      "roll",   "rub",   "tap",    "drop",  "point", "use",    "pump",  "balance", "straighten",
      "curl",   "stomp", "step",   "shrug", "nod",   "look",   "lean",  "sway",    "wiggle",
      "throw",  "kick",  "stand",  "land",  "set",   "get",    "make"};
  return words;
}

// Words that may stand between a verb and the body part it moves.
const std::unordered_set<std::string>& Fillers() {
  static const std::unordered_set<std::string> words = {
      "the", "a",    "an",  "his", "her", "their", "its",   "one", "both", "left",  "right", "with",
      "up",  "down", "out", "on",  "in",  "upper", "lower", "two", "each", "other", "over",  "at"};
  return words;
}

const std::unordered_set<std::string>& NegationWords() {
  static const std::unordered_set<std::string> words = {
      "without", "not",        "no",         "dont",     "don't", "never",
      "still",   "motionless", "stationary", "unmoving", "keep",  "keeping"};
  return words;
}

std::string Lower(const std::string& s) {
  std::string out;
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    out.push_back(std::isalnum(u) || c == '\'' ? static_cast<char>(std::tolower(u)) : ' ');
  }
  return out;
}

std::vector<std::string> Tokens(const std::string& text) {
  std::vector<std::string> out;
  std::string word;
  for (char c : Lower(text) + " ") {
    if (c == ' ') {
      if (!word.empty()) out.push_back(word);
      word.clear();
    } else if (c != '\'') {
      word.push_back(c);
    }
  }
  return out;
}

// walking -> walk, waves -> wave, reaches -> reach, tries -> try; unknown forms come back
// unchanged.
std::string VerbBase(const std::string& w) {
  const auto& verbs = Verbs();
  if (verbs.count(w)) return w;
  const size_t n = w.size();
  auto known = [&](const std::string& c) { return verbs.count(c) > 0; };
  if (n > 4 && w.compare(n - 3, 3, "ing") == 0) {
    const std::string stem = w.substr(0, n - 3);
    if (known(stem)) return stem;
    if (known(stem + "e")) return stem + "e";  // waving -> wave
    if (stem.size() > 2 && stem[stem.size() - 1] == stem[stem.size() - 2] &&
        known(stem.substr(0, stem.size() - 1))) {
      return stem.substr(0, stem.size() - 1);  // running -> run
    }
    if (stem.size() > 1 && stem.back() == 'y' && known(stem.substr(0, stem.size() - 1) + "ie")) {
      return stem.substr(0, stem.size() - 1) + "ie";  // lying -> lie
    }
  }
  if (n > 3 && w.back() == 's') {
    if (known(w.substr(0, n - 1))) return w.substr(0, n - 1);
    if (n > 4 && w.compare(n - 2, 2, "es") == 0 && known(w.substr(0, n - 2)))
      return w.substr(0, n - 2);
    if (n > 4 && w.compare(n - 3, 3, "ies") == 0 && known(w.substr(0, n - 3) + "y"))
      return w.substr(0, n - 3) + "y";
  }
  if (n > 3 && w.compare(n - 2, 2, "ed") == 0) {
    if (known(w.substr(0, n - 2))) return w.substr(0, n - 2);
    if (known(w.substr(0, n - 1))) return w.substr(0, n - 1);
  }
  return w;
}

}  // namespace

PartSet LexiconParts(const std::string& text) {
  std::vector<std::string> tokens = Tokens(text);
  // Fixed phrases whose words would mislead one by one.
  PartSet phrase_parts = 0;
  for (size_t k = 0; k + 1 < tokens.size(); ++k) {
    const std::string two = tokens[k] + " " + tokens[k + 1];
    PartSet p = 0;
    if (two == "jumping jacks" || two == "jumping jack" || two == "star jumps")
      p = G | T | kArms | kLegs;
    if (two == "arm circles" || two == "arm circle") p = kArms;
    if (two == "t pose" || two == "a pose") p = T | kArms;
    const bool filler = two == "in place" || two == "the spot" ||
                        two == "in front";  // not the verbs place/spot/front
    if (p == 0 && !filler) continue;
    phrase_parts |= p;
    tokens.erase(tokens.begin() + static_cast<std::ptrdiff_t>(k),
                 tokens.begin() + static_cast<std::ptrdiff_t>(k) + 2);
    --k;
  }
  const auto& nouns = Nouns();
  const auto& verbs = Verbs();
  PartSet verb_parts = 0, noun_parts = 0, negated = 0;
  PartSet arm_sides = 0, leg_sides = 0;  // sides named by nouns
  bool arm_noun = false, leg_noun = false;
  int negation_left = 0;  // tokens still inside a negated phrase
  for (size_t k = 0; k < tokens.size(); ++k) {
    const std::string& w = tokens[k];
    if (NegationWords().count(w)) {
      negation_left =
          (w == "still" || w == "motionless" || w == "stationary" || w == "unmoving") ? 0 : 5;
      if (w == "still" || w == "motionless" || w == "stationary" || w == "unmoving") {
        // "legs still", "keep the arms motionless": the noun just before is negated.
        for (size_t back = k; back-- > 0 && back + 3 >= k;) {
          const auto it = nouns.find(tokens[back]);
          if (it == nouns.end()) continue;
          if (it->second.limb == Limb::kArm) negated |= kArms;
          if (it->second.limb == Limb::kLeg) negated |= kLegs;
          negated |= it->second.parts;
          break;
        }
      }
      continue;
    }
    const auto noun = nouns.find(w);
    if (noun != nouns.end() &&
        !(w == "hand" && k + 1 < tokens.size() && nouns.count(tokens[k + 1]) == 0 &&
          k == 0)) {  // "hand over" as a verb
      const Noun& n = noun->second;
      // A side within the two words before: "left hand", "right upper arm"; "both"/"either" = both.
      PartSet side = 0;  // bit 1 = left, bit 2 = right
      bool both = n.plural;
      (void)both;
      for (size_t back = k; back-- > 0 && back + 3 >= k;) {
        if (tokens[back] == "left") side |= 1;
        if (tokens[back] == "right") side |= 2;
        if (tokens[back] == "both" || tokens[back] == "two" || tokens[back] == "either")
          both = true;
      }
      if (side == 0)
        side = 3;  // an unsided limb ("raise arm", "wave hand"): both, as GPT mostly answers
      const PartSet arm = static_cast<PartSet>(((side & 1) ? LA : 0) | ((side & 2) ? RA : 0));
      const PartSet leg = static_cast<PartSet>(((side & 1) ? LL : 0) | ((side & 2) ? RL : 0));
      if (negation_left > 0) {
        if (n.limb == Limb::kArm) negated |= arm;
        if (n.limb == Limb::kLeg) negated |= leg;
        negated |= n.parts;
        continue;
      }
      if (n.limb == Limb::kArm) {
        arm_noun = true;
        arm_sides |= arm;
      } else if (n.limb == Limb::kLeg) {
        leg_noun = true;
        leg_sides |= leg;
      }
      noun_parts |= n.parts;
      continue;
    }
    if (negation_left > 0) {
      --negation_left;
      // "without moving": a verb inside the negated phrase does not count.
      continue;
    }
    const std::string base = VerbBase(w);
    const auto verb = verbs.find(base);
    if (verb == verbs.end()) continue;
    if (GenericVerbs().count(base)) {
      // "bend knees", "raise both arms", "arms move up": the noun decides.
      bool object = false;
      for (size_t ahead = k + 1; ahead < tokens.size() && ahead <= k + 4; ++ahead) {
        if (nouns.count(tokens[ahead])) {
          object = true;
          break;
        }
        if (!Fillers().count(tokens[ahead])) break;
      }
      if (k > 0 && nouns.count(tokens[k - 1])) object = true;
      if (object) continue;
    }
    // "bend down", "crouch down": the legs take the body down.
    if ((base == "bend" || base == "lean") && k + 1 < tokens.size() &&
        (tokens[k + 1] == "down" || tokens[k + 1] == "over")) {
      verb_parts |=
          tokens[k + 1] == "down" ? static_cast<PartSet>(G | kLegs) : static_cast<PartSet>(G | T);
      continue;
    }
    verb_parts |= verb->second;
  }
  // Nouns decide a limb's sides over a verb's default ("raise left arm" -> left arm only).
  PartSet parts =
      static_cast<PartSet>((verb_parts & static_cast<PartSet>(G | T)) | noun_parts | phrase_parts);
  parts |= arm_noun ? arm_sides : static_cast<PartSet>(verb_parts & kArms);
  parts |= leg_noun ? leg_sides : static_cast<PartSet>(verb_parts & kLegs);
  // A side word with an arm verb and no noun: "punch right", "wave left".
  if (!arm_noun && (verb_parts & kArms)) {
    const bool left = std::find(tokens.begin(), tokens.end(), "left") != tokens.end();
    const bool right = std::find(tokens.begin(), tokens.end(), "right") != tokens.end();
    // "turn left", "step right", "lean left": the side is a direction, not an arm.
    static const std::unordered_set<std::string> directions = {
        "turn", "rotate", "look", "lean", "face", "twist",  "spin",
        "step", "move",   "go",   "tilt", "bend", "glance", "pivot"};
    bool directional = (verb_parts & kLegs) != 0;
    for (const std::string& t : tokens)
      directional = directional || directions.count(VerbBase(t)) > 0;
    if (!directional && left != right)
      parts = static_cast<PartSet>((parts & ~kArms) | (left ? LA : RA));
  }
  parts = static_cast<PartSet>(parts & ~negated);
  // Nothing recognised: GPT's answer to vague actions ("argue", "adopt ready pose") is the upper
  // body.
  if (parts == 0 && negated == 0) parts = static_cast<PartSet>(T | kArms);
  return parts;
}

}  // namespace motionpipe::labels
