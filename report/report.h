// The HTML report of a job (`motionpipe report JOB_DIR`, the `report` stage): one self-contained
// file with the evaluation stages' metrics laid out as the papers' tables (papers.h: each table's
// rows, published numbers and claims are data, configs/papers/*.yaml; an editing table holds
// motion-to-motion retrieval, a generation table TEMOS score, APE/AVE and retrieval), methods
// as rows, mean ± standard deviation over seed replicates, the best of each column in bold and the
// papers' own numbers beside them; the claims each paper makes, checked against these runs;
// physical plausibility; training curves and the metric history as plots; rendered previews (GIFs)
// of the edits and generations; the CMU showcase when the job has one. Images are embedded as data:
// URIs.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe::report {

struct ReportOptions {
  std::string job_dir;   // a job's output directory (out/<name>-<id>)
  std::string out_path;  // default: <job_dir>/report.html
  std::string history;   // optional evaluation history (SQLite) to plot
  std::string title;     // default: the job directory's name
  bool previews = true;  // render GIF previews (the slow part: about a second per method)
  int panel_size = 200;  // preview panel width and height in pixels
  // Paper files (configs/papers/*.yaml's format) beside the built-in ones: one of the same
  // paper name replaces the built-in, others add a table.
  std::vector<std::string> papers;
};

struct ClaimCheck {
  std::string paper, claim;
  std::string verdict;  // "holds", "does not hold", "not decided: ...", "not decidable: ...", "not
                        // measured"
  std::string detail;   // the numbers behind the verdict
};

struct ReportSummary {
  std::string path;
  int tables = 0, images = 0;
  int train_stages = 0;
  std::map<std::string, int> methods;  // evaluated methods by evaluation kind ("edit": 9, ...)
  std::vector<ClaimCheck> claims;
};

Result<ReportSummary> WriteReport(const ReportOptions& options);

// A paper's claim "better beats worse" on a metric, from each side's values over seeds (issue 15):
// not decidable while a compared model does not beat its untrained row (`untrained` empty: no such
// row) by more than two standard errors, or with fewer than 3 seeds a side; otherwise it holds when
// the difference of the means goes the claimed way by more than two standard errors of the
// difference, does not hold when it goes the other way by as much, and is within them in between.
// With `paired`, better[k] and worse[k] are the same seed's replicates (a pipeline's `seeds: N`
// gives replicate k of every stage the seed base + k - 1: the same initial weights and batch order
// for models of one architecture), and the standard error of the difference is that of the n
// per-seed differences: the spread the seed gives both sides cancels. It is a valid standard
// error for any pairing of independent runs too (their differences are then independent), so a
// pairing of unrelated seeds costs power, not correctness.
enum class ClaimVerdict {
  kHolds,
  kDoesNotHold,
  kWithinErrors,
  kFewSeeds,
  kBetterNotTrained,
  kWorseNotTrained
};
ClaimVerdict DecideClaim(const std::vector<double>& better, const std::vector<double>& worse,
                         const std::vector<double>& untrained, bool higher_is_better);
// The same with each side's own untrained row (an untrained MDM generates noise where an untrained
// source-prior editor copies its source: each model must beat its own).
ClaimVerdict DecideClaim(const std::vector<double>& better, const std::vector<double>& worse,
                         const std::vector<double>& better_untrained,
                         const std::vector<double>& worse_untrained, bool higher_is_better,
                         bool paired = false);
// The two standard errors a claim's difference must beat: of the per-seed differences when
// `paired` (same sizes), else of the difference of two independent means.
double TwoStandardErrors(const std::vector<double>& better, const std::vector<double>& worse,
                         bool paired);

// Seconds of training until a validated R@1 first reached `bar` (the training table's time to a
// retrieval quality): seconds[k] of the first k with r1[k] >= bar; nullopt if none did (or the two
// columns differ in length).
std::optional<double> SecondsToReach(const std::vector<double>& r1,
                                     const std::vector<double>& seconds, double bar);

// Base64 (RFC 4648, with padding): the report's data: URIs.
std::string Base64(std::string_view bytes);

}  // namespace motionpipe::report
