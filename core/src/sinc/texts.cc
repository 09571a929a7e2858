#include "motionpipe/sinc/texts.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <sstream>
#include <unordered_set>
#include <vector>

#include "motionpipe/text/english.h"

namespace motionpipe::sinc {

namespace {

std::vector<std::string> Words(const std::string& text) {
  std::vector<std::string> words;
  std::istringstream in(text);
  std::string word;
  while (in >> word) words.push_back(word);
  return words;
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Words ending in -s that are not third-person verbs when they lead a label.
const std::unordered_set<std::string>& NotVerbs() {
  static const std::unordered_set<std::string> words = {
      "arms",    "legs",    "hands",     "feet",     "knees",    "hips",    "shoulders",
      "jumping", "jacks",   "stairs",    "steps",    "this",     "is",      "was",
      "has",     "yes",     "its",       "his",      "hers",     "always",  "sometimes",
      "across",  "towards", "backwards", "forwards", "sideways", "upwards", "downwards",
      "pass",    "press",   "toss",      "cross",    "kiss",     "dress",   "bless",
      "guess",   "miss",    "dismiss",   "caress",   "focus",    "bus",     "chess",
      "plus",    "minus",   "less"};
  return words;
}

// "swings" -> "swing"; words that are not third-person verbs come back unchanged.
std::string BaseForm(const std::string& word) {
  const std::string lower = Lower(word);
  const size_t n = lower.size();
  if (n < 3 || lower.back() != 's' || NotVerbs().count(lower)) return word;
  if (lower == "goes") return word.substr(0, 2);
  if (lower == "does") return word.substr(0, 2);
  if (lower == "has") return "have";
  if (n > 4 && lower.compare(n - 3, 3, "ies") == 0)
    return word.substr(0, n - 3) + "y";  // tries -> try
  for (const char* ending : {"ches", "shes", "sses", "xes", "zes", "oes"}) {
    const size_t e = std::strlen(ending);
    if (n > e && lower.compare(n - e, e, ending) == 0)
      return word.substr(0, n - 2);  // reaches -> reach
  }
  if (lower.compare(n - 2, 2, "ss") == 0 || lower.compare(n - 2, 2, "us") == 0 ||
      lower.compare(n - 2, 2, "is") == 0) {
    return word;
  }
  return word.substr(0, n - 1);
}

}  // namespace

std::string VerbPhrase(const std::string& label) {
  std::vector<std::string> words = Words(label);
  size_t start = 0;
  // Subjects: "a person", "the person", "someone", "a man", "the figure", pronouns.
  static const std::unordered_set<std::string> determiners = {"a", "an", "the", "this"};
  static const std::unordered_set<std::string> nouns = {
      "person",     "man",     "woman", "human",  "figure", "character",
      "individual", "subject", "guy",   "people", "actor"};
  static const std::unordered_set<std::string> pronouns = {"someone", "somebody", "he",    "she",
                                                           "they",    "it",       "person"};
  if (start + 1 < words.size() && determiners.count(Lower(words[start])) &&
      nouns.count(Lower(words[start + 1]))) {
    start += 2;
  } else if (start < words.size() && pronouns.count(Lower(words[start])) && words.size() > 1) {
    start += 1;
  }
  // Auxiliaries before a gerund: "is walking" -> "walking".
  if (start + 1 < words.size() && (Lower(words[start]) == "is" || Lower(words[start]) == "are"))
    start += 1;
  if (start == words.size()) return label;
  std::string out;
  for (size_t k = start; k < words.size(); ++k) {
    if (!out.empty()) out += ' ';
    out += words[k];
  }
  // A conjugated leading verb ("a person walks", BABEL's "swings arms forward") returns to its
  // base.
  const size_t space = out.find(' ');
  return BaseForm(out.substr(0, space)) + (space == std::string::npos ? "" : out.substr(space));
}

std::string GerundOfLabel(const std::string& label) {
  return text::GerundPhrase(VerbPhrase(label));
}

std::string PairText(const std::string& first, const std::string& second, PairPattern pattern) {
  switch (pattern) {
    case PairPattern::kWhile:
      return first + " while " + GerundOfLabel(second);
    case PairPattern::kSimultaneously:
      return "simultaneously " + first + " and " + second;
    case PairPattern::kComma:
      return first + ", " + second;
    case PairPattern::kAtTheSameTime:
      return first + " and " + second + " at the same time";
    case PairPattern::kDuring:
      return first + " during " + GerundOfLabel(second);
  }
  return first + " while " + GerundOfLabel(second);
}

std::string AugmentPairText(const std::string& a, const std::string& b, Rng& rng,
                            PairPattern* pattern_out, bool* swapped_out) {
  const bool swapped = rng.Bernoulli(0.5);
  const auto pattern = static_cast<PairPattern>(rng.Int(0, kNumPairPatterns - 1));
  if (pattern_out) *pattern_out = pattern;
  if (swapped_out) *swapped_out = swapped;
  return swapped ? PairText(b, a, pattern) : PairText(a, b, pattern);
}

}  // namespace motionpipe::sinc
