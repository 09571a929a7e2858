#include "motionpipe/text/english.h"

#include <cctype>
#include <string_view>
#include <unordered_map>
#include <unordered_set>

namespace motionpipe::text {

namespace {

bool IsVowel(char c) { return c == 'a' || c == 'e' || c == 'i' || c == 'o' || c == 'u'; }

// Verbs whose last syllable is unstressed: no doubling (visit -> visiting).
const std::unordered_set<std::string_view>& Unstressed() {
  static const std::unordered_set<std::string_view> words = {
      "visit",   "open",    "listen",  "happen",  "enter",      "offer",   "order",  "answer",
      "gather",  "wander",  "whisper", "shiver",  "flicker",    "hover",   "lower",  "alter",
      "balance", "pivot",   "budget",  "limit",   "edit",       "exit",    "gallop", "develop",
      "travel",  "cancel",  "model",   "signal",  "level",      "label",   "shovel", "swivel",
      "paddle",  "target",  "market",  "profit",  "credit",     "orbit",   "summon", "beckon",
      "reckon",  "sharpen", "widen",   "fasten",  "straighten", "tighten", "loosen", "lessen",
      "deepen",  "flatten", "soften",  "stiffen", "waken",      "darken"};
  return words;
}

// Two-syllable verbs stressed on the last syllable: the consonant doubles (begin -> beginning).
const std::unordered_set<std::string_view>& StressedFinal() {
  static const std::unordered_set<std::string_view> words = {
      "begin",  "forget", "prefer", "admit",  "regret", "occur",  "control",  "patrol",
      "permit", "commit", "submit", "equip",  "refer",  "compel", "expel",    "propel",
      "rebel",  "upset",  "outrun", "forbid", "unzip",  "kidnap", "handicap", "transmit",
      "omit",   "acquit", "allot",  "abet",   "deter",  "confer", "infer",    "defer"};
  return words;
}

const std::unordered_map<std::string_view, std::string_view>& Irregular() {
  static const std::unordered_map<std::string_view, std::string_view> words = {
      {"be", "being"},
      {"see", "seeing"},
      {"flee", "fleeing"},
      {"agree", "agreeing"},
      {"dye", "dyeing"},
      {"lie", "lying"},
      {"die", "dying"},
      {"tie", "tying"},
      {"vie", "vying"},
      {"ski", "skiing"},
      {"panic", "panicking"},
      {"picnic", "picnicking"},
      {"mimic", "mimicking"},
      {"traffic", "trafficking"},
      {"singe", "singeing"},
      {"age", "ageing"},
      {"canoe", "canoeing"},
      {"hoe", "hoeing"},
      {"toe", "toeing"},
      {"tiptoe", "tiptoeing"},
      {"shoe", "shoeing"},
      {"free", "freeing"},
      {"guarantee", "guaranteeing"},
      {"referee", "refereeing"},
      {"knee", "kneeing"}};
  return words;
}

}  // namespace

std::string Gerund(const std::string& verb) {
  if (verb.empty()) return verb;
  std::string lower;
  for (char c : verb)
    lower.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  // Already a gerund: "-ing" after a stem with a vowel ("walking"), unlike "swing", "bring",
  // "sing".
  if (lower.size() > 3 && lower.compare(lower.size() - 3, 3, "ing") == 0 &&
      lower.find_first_of("aeiouy") < lower.size() - 3) {
    return verb;
  }
  if (const auto it = Irregular().find(lower); it != Irregular().end()) {
    std::string out(it->second);
    if (std::isupper(static_cast<unsigned char>(verb[0])))
      out[0] = static_cast<char>(std::toupper(static_cast<unsigned char>(out[0])));
    return out;
  }
  const size_t n = verb.size();
  if (n >= 2 && lower.compare(n - 2, 2, "ie") == 0) return verb.substr(0, n - 2) + "ying";
  if (n >= 2 && lower[n - 1] == 'e' && lower[n - 2] != 'e' && lower[n - 2] != 'y' &&
      lower[n - 2] != 'o') {
    return verb.substr(0, n - 1) + "ing";  // wave -> waving, stroke -> stroking
  }
  if (n >= 3 && !Unstressed().count(lower)) {
    const char a = lower[n - 3], b = lower[n - 2], c = lower[n - 1];
    // consonant + single vowel + consonant (kneel and look have vowel teams and do not double)
    const bool cvc = !IsVowel(a) && IsVowel(b) && !IsVowel(c) && c != 'w' && c != 'x' && c != 'y';
    // "qu" acts as a consonant: squat -> squatting, quit -> quitting
    const bool qu = n >= 4 && lower[n - 4] == 'q' && a == 'u' && IsVowel(b) && !IsVowel(c);
    if (cvc || qu) {
      int groups = 0;  // vowel groups; the u of "qu" does not count
      for (size_t k = 0; k < n; ++k) {
        const bool vowel = IsVowel(lower[k]) && !(lower[k] == 'u' && k > 0 && lower[k - 1] == 'q');
        const bool prev_vowel = k > 0 && IsVowel(lower[k - 1]) &&
                                !(lower[k - 1] == 'u' && k > 1 && lower[k - 2] == 'q');
        groups += vowel && !prev_vowel;
      }
      if (groups <= 1 || StressedFinal().count(lower)) return verb + verb.substr(n - 1) + "ing";
    }
  }
  return verb + "ing";
}

std::string GerundPhrase(const std::string& phrase) {
  const size_t space = phrase.find(' ');
  if (space == std::string::npos) return Gerund(phrase);
  return Gerund(phrase.substr(0, space)) + phrase.substr(space);
}

}  // namespace motionpipe::text
