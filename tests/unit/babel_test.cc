#include "motionpipe/formats/babel.h"

#include <gtest/gtest.h>

namespace motionpipe {
namespace {

constexpr char kBabel[] = R"({
  "11": {"babel_sid": 11, "feat_p": "CMU/1/01_01_poses.npz", "dur": 10.0,
         "seq_ann": {"labels": [{"proc_label": "walk", "raw_label": "walking", "act_cat": ["walk"]}]},
         "frame_ann": {"labels": [
            {"proc_label": "walk", "raw_label": "walk forward", "act_cat": ["walk"], "start_t": 0.0, "end_t": 6.0},
            {"proc_label": "wave", "raw_label": "waves right hand", "act_cat": ["gesture"], "start_t": 2.0, "end_t": 4.0},
            {"proc_label": "transition", "raw_label": "transition", "act_cat": ["transition"], "start_t": 6.0, "end_t": 7.0},
            {"proc_label": "stand", "raw_label": "stand", "act_cat": ["stand"], "start_t": 7.0, "end_t": 10.0},
            {"proc_label": "T pose", "raw_label": "tpose", "act_cat": ["t pose"], "start_t": 9.5, "end_t": 10.0}]}},
  "12": {"babel_sid": 12, "feat_p": "x.npz", "dur": 3.0,
         "seq_ann": {"labels": [{"proc_label": "jump", "raw_label": "jump", "act_cat": ["jump"]}]},
         "frame_ann": null}
})";

TEST(Babel, ParsesFrameAndSequenceAnnotations) {
  auto seqs = ParseBabel(kBabel, "babel.json");
  ASSERT_TRUE(seqs.ok()) << seqs.status().ToString();
  ASSERT_EQ(seqs->size(), 2u);
  EXPECT_TRUE((*seqs)[0].frame_level);
  EXPECT_EQ((*seqs)[0].labels.size(), 5u);
  EXPECT_EQ((*seqs)[0].feat_p, "CMU/1/01_01_poses.npz");
  EXPECT_FALSE((*seqs)[1].frame_level);
  EXPECT_EQ((*seqs)[1].labels[0].end_t, 3.0);  // seq_ann spans the whole sequence
}

TEST(Babel, SweepFindsSinglesAndSimultaneousPairs) {
  auto seqs = ParseBabel(kBabel, "babel.json");
  ASSERT_TRUE(seqs.ok());
  const std::vector<ActionSpan> spans = SweepActionSpans((*seqs)[0], {});
  // walk [0,60) | walk+wave [60,120) | walk [120,180) | (transition dropped) | stand [210,300)
  ASSERT_EQ(spans.size(), 4u);
  EXPECT_EQ(spans[0].labels, std::vector<std::string>{"walk"});
  EXPECT_EQ(spans[0].end_frame, 60);
  EXPECT_EQ(spans[1].labels, (std::vector<std::string>{"walk", "wave"}));
  EXPECT_EQ(spans[1].start_frame, 60);
  EXPECT_EQ(spans[1].end_frame, 120);
  EXPECT_EQ(spans[3].labels, std::vector<std::string>{"stand"});
  EXPECT_EQ(spans[3].start_frame, 210);
  EXPECT_EQ(spans[3].end_frame, 300);  // the t-pose label is excluded, so stand goes on
  BabelSpanOptions strict;
  strict.max_frames = 59;
  EXPECT_EQ(SweepActionSpans((*seqs)[0], strict).size(), 0u);
  strict = {};
  strict.max_actions = 1;
  EXPECT_EQ(SweepActionSpans((*seqs)[0], strict).size(), 3u);
}

TEST(Babel, AdjacentLabelsWithTheSameActionFormOneSpan) {
  auto seqs = ParseBabel(R"({"1": {"dur": 4, "frame_ann": {"labels": [
      {"proc_label": "walk", "start_t": 0, "end_t": 2}, {"proc_label": "walk", "start_t": 2, "end_t": 4}]}}})",
                         "b.json");
  ASSERT_TRUE(seqs.ok());
  const auto spans = SweepActionSpans((*seqs)[0], {});
  ASSERT_EQ(spans.size(), 1u);
  EXPECT_EQ(spans[0].end_frame, 120);
}

TEST(Babel, ExcludedLabelSpellings) {
  for (const char* label :
       {"t-pose", "T pose", "tpose", "a-pose", "A Pose", "transition", "Transition"}) {
    EXPECT_TRUE(IsExcludedBabelLabel(label)) << label;
  }
  EXPECT_FALSE(IsExcludedBabelLabel("pose"));
  EXPECT_FALSE(IsExcludedBabelLabel("walk"));
}

TEST(Babel, MalformedInputNamesFileAndSequence) {
  auto broken = ParseBabel("{\"1\": {", "ann.json");
  ASSERT_FALSE(broken.ok());
  EXPECT_NE(broken.status().message().find("ann.json: malformed JSON"), std::string::npos);
  auto no_times = ParseBabel(
      R"({"7": {"dur": 2, "frame_ann": {"labels": [{"proc_label": "walk"}]}}})", "ann.json");
  ASSERT_FALSE(no_times.ok());
  EXPECT_NE(no_times.status().message().find("sequence '7'"), std::string::npos);
  EXPECT_NE(no_times.status().message().find("start_t"), std::string::npos);
  auto backwards = ParseBabel(
      R"({"7": {"dur": 2, "frame_ann": {"labels": [{"proc_label": "w", "start_t": 2, "end_t": 1}]}}})",
      "a.json");
  EXPECT_FALSE(backwards.ok());
  EXPECT_FALSE(ParseBabel("[1, 2]", "a.json").ok());
  EXPECT_FALSE(
      ParseBabel(R"({"7": {"frame_ann": null, "seq_ann": null, "dur": 1}})", "a.json").ok());
}

}  // namespace
}  // namespace motionpipe
