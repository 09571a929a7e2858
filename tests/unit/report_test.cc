// The report's calibrated claim verdicts (issue 15): a claim is decided only between models that
// learned (each beats the untrained row) with 3+ seeds a side, by two standard errors.
#include "report.h"

#include <gtest/gtest.h>

namespace motionpipe::worker {
namespace {

TEST(Claims, NotDecidableWhileAComparedModelDoesNotBeatItsUntrainedRow) {
  // Both near chance (the demo before issue 15): the untrained row is as good.
  EXPECT_EQ(DecideClaim({4.2, 3.1, 5.2}, {5.2, 5.2, 5.2}, {4.0}, true),
            ClaimVerdict::kBetterNotTrained);
  // The better one learned, the worse one did not.
  EXPECT_EQ(DecideClaim({40, 42, 41}, {4, 6, 5}, {5}, true), ClaimVerdict::kWorseNotTrained);
  // Beating the untrained row by less than two standard errors of the seeds is not beating it.
  EXPECT_EQ(DecideClaim({4, 14, 9}, {30, 31, 32}, {5}, true), ClaimVerdict::kBetterNotTrained);
  // Lower-is-better metrics (AvgR): the untrained row's is higher.
  EXPECT_EQ(DecideClaim({3.0, 3.1, 2.9}, {16.6, 16.4, 16.5}, {16.5}, false),
            ClaimVerdict::kWorseNotTrained);
}

TEST(Claims, FewerThanThreeSeedsDecideNothing) {
  EXPECT_EQ(DecideClaim({60, 61}, {30, 31}, {5}, true), ClaimVerdict::kFewSeeds);
  EXPECT_EQ(DecideClaim({60}, {30, 31, 32}, {}, true), ClaimVerdict::kFewSeeds);
}

TEST(Claims, HoldsOrFailsOnlyBeyondTwoStandardErrors) {
  // Differences of 10 with standard errors of about 0.8: decided either way.
  EXPECT_EQ(DecideClaim({60, 61, 62}, {50, 51, 52}, {5}, true), ClaimVerdict::kHolds);
  EXPECT_EQ(DecideClaim({50, 51, 52}, {60, 61, 62}, {5}, true), ClaimVerdict::kDoesNotHold);
  // A difference of 1 with standard errors of about 2.3 is not decided.
  EXPECT_EQ(DecideClaim({58, 61, 64}, {57, 60, 63}, {5}, true), ClaimVerdict::kWithinErrors);
  // No untrained row in the job: the seeds alone decide.
  EXPECT_EQ(DecideClaim({0.70, 0.71, 0.72}, {0.60, 0.61, 0.62}, {}, true), ClaimVerdict::kHolds);
  // Lower is better: 2.4 against 2.7 holds.
  EXPECT_EQ(DecideClaim({2.40, 2.41, 2.39}, {2.70, 2.71, 2.69}, {16}, false), ClaimVerdict::kHolds);
}

}  // namespace
}  // namespace motionpipe::worker
