#include "motionpipe/text/english.h"

#include <gtest/gtest.h>

namespace motionpipe::text {
namespace {

TEST(Gerund, EnglishSpellingRules) {
  const std::pair<const char*, const char*> cases[] = {
      {"wave", "waving"},     {"sit", "sitting"},      {"lie", "lying"},
      {"kneel", "kneeling"},  {"run", "running"},      {"hop", "hopping"},
      {"jog", "jogging"},     {"squat", "squatting"},  {"nod", "nodding"},
      {"clap", "clapping"},   {"step", "stepping"},    {"stomp", "stomping"},
      {"visit", "visiting"},  {"open", "opening"},     {"begin", "beginning"},
      {"bow", "bowing"},      {"fix", "fixing"},       {"play", "playing"},
      {"see", "seeing"},      {"tiptoe", "tiptoeing"}, {"dance", "dancing"},
      {"look", "looking"},    {"point", "pointing"},   {"wait", "waiting"},
      {"quit", "quitting"},   {"kick", "kicking"},     {"shuffle", "shuffling"},
      {"walking", "walking"}, {"Wave", "Waving"},      {"die", "dying"}};
  for (const auto& [verb, gerund] : cases) EXPECT_EQ(Gerund(verb), gerund) << verb;
}

TEST(Gerund, VerbsEndingInIngAreNotGerundsYet) {
  EXPECT_EQ(Gerund("swing"), "swinging");
  EXPECT_EQ(Gerund("bring"), "bringing");
  EXPECT_EQ(Gerund("sing"), "singing");
  EXPECT_EQ(Gerund("walking"), "walking");
  EXPECT_EQ(Gerund("lying"), "lying");
}

TEST(Gerund, AppliesToTheFirstWordOfAPhrase) {
  EXPECT_EQ(GerundPhrase("walk forward"), "walking forward");
  EXPECT_EQ(GerundPhrase("wave with the right hand"), "waving with the right hand");
  EXPECT_EQ(GerundPhrase("sit"), "sitting");
}

}  // namespace
}  // namespace motionpipe::text
