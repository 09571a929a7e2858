// Small English helpers for generated texts: gerunds that are right for English ("wave" ->
// "waving", "sit" -> "sitting", "lie" -> "lying", "kneel" -> "kneeling"), applied to the first word
// of a verb phrase ("wave right hand" -> "waving right hand").
#pragma once

#include <string>

namespace motionpipe::text {

// The -ing form of a single verb. Rules: irregular table; "ie" -> "ying"; silent final e dropped
// (but "be", "see", "flee", "dye" keep it); a stressed final consonant-vowel-consonant doubles its
// consonant (sit, run, hop, jog, nod, clap, step, squat), never w, x or y, and not after a vowel
// team (kneel, look) or in unstressed two-syllable verbs (visit, open, listen) listed as
// exceptions.
std::string Gerund(const std::string& verb);

// Gerund of the first word of a phrase; the rest is kept ("walk forward" -> "walking forward").
std::string GerundPhrase(const std::string& phrase);

}  // namespace motionpipe::text
