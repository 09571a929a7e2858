// The report's calibrated claim verdicts (issue 15): a claim is decided only between models that
// learned (each beats the untrained row) with 3+ seeds a side, by two standard errors. The papers'
// tables are data (configs/papers/*.yaml): a third paper's table is one file.
#include "report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "motionpipe/base/file.h"
#include "papers.h"

namespace motionpipe::report {
namespace {

// An edit evaluation's metrics.json in a job directory: generated-to-target R@1 in batches.
void WriteEditEval(const std::string& job, const std::string& stage, double r1,
                   const nlohmann::json& extra) {
  nlohmann::json m = {{"evaluation", "edit"},
                      {"motions", 64},
                      {"generated_to_target", {{"batches", {{"R@1", r1}, {"queries", 64}}}}}};
  m.update(extra);
  std::filesystem::create_directories(job + "/" + stage + "/task-00000");
  ASSERT_TRUE(WriteFileAtomic(job + "/" + stage + "/task-00000/metrics.json", m.dump()).ok());
}

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

TEST(Claims, EachSideIsJudgedAgainstItsOwnUntrainedRow) {
  // A generator without a source (MDM, 15) is far below an untrained source-prior editor (a copy,
  // 66) but far above its own untrained row (noise, 3): judged against its own, it learned.
  EXPECT_EQ(DecideClaim({69, 70, 71}, {14, 15, 16}, {66}, {3}, true), ClaimVerdict::kHolds);
  EXPECT_EQ(DecideClaim({69, 70, 71}, {14, 15, 16}, {66}, true), ClaimVerdict::kWorseNotTrained);
  // The better side below its own untrained row, the worse above its own: still not decidable.
  EXPECT_EQ(DecideClaim({60, 61, 62}, {14, 15, 16}, {66}, {3}, true),
            ClaimVerdict::kBetterNotTrained);
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

TEST(Claims, TheSameSeedsOnBothSidesArePaired) {
  // Each seed moves both sides alike (the same initial weights and batch order): unpaired, the
  // seeds' spread hides a difference of 0.01; paired, the per-seed differences (0.012, 0.009,
  // 0.009) decide it.
  const std::vector<double> better = {0.800, 0.840, 0.780}, worse = {0.788, 0.831, 0.771};
  EXPECT_EQ(DecideClaim(better, worse, {}, {}, true), ClaimVerdict::kWithinErrors);
  EXPECT_EQ(DecideClaim(better, worse, {}, {}, true, /*paired=*/true), ClaimVerdict::kHolds);
  EXPECT_EQ(DecideClaim(worse, better, {}, {}, true, /*paired=*/true), ClaimVerdict::kDoesNotHold);
  EXPECT_NEAR(TwoStandardErrors(better, worse, true), 2 * std::sqrt(3e-6 / 3), 1e-9);
  // Differences of both signs (0.02, -0.01, 0.02) are not decided, paired or not.
  EXPECT_EQ(DecideClaim({0.80, 0.84, 0.78}, {0.78, 0.85, 0.76}, {}, {}, true, true),
            ClaimVerdict::kWithinErrors);
  // Sides of different sizes cannot pair: the unpaired standard error.
  EXPECT_DOUBLE_EQ(TwoStandardErrors({1, 2, 3, 4}, {1, 2, 3}, true),
                   TwoStandardErrors({1, 2, 3, 4}, {1, 2, 3}, false));
  EXPECT_EQ(DecideClaim(better, {0.788, 0.831}, {}, {}, true, true), ClaimVerdict::kFewSeeds);
}

// In a job the runs pair by replicate (stage name-sk) when both rows hold the same 3+ replicates.
TEST(Claims, AJobsReplicatesPairBySeed) {
  namespace fs = std::filesystem;
  const std::string dir = ::testing::TempDir() + "/paired";
  const auto report = [&](const std::vector<std::string>& mdm_replicates) {
    fs::remove_all(dir);
    const auto eval = [&](const std::string& stage, double r1, const nlohmann::json& extra) {
      WriteEditEval(dir + "/job", stage, r1, extra);
    };
    // Seeds 1, 2, 3 (and 10, read before 2 by name) give both rows 70, 60, 80, 50 give or take.
    const std::vector<std::string> replicates = {"", "-s2", "-s3", "-s10"};
    const double mdt[] = {70, 60, 80, 50}, mdm[] = {68.5, 58, 78.8, 48.6};
    for (int k = 0; k < 4; ++k)
      eval("eval_mdt" + replicates[k], mdt[k], {{"method", "MDT"}, {"row", "SimMotionEdit (MDT)"}});
    for (int k = 0; k < 4; ++k)
      eval("eval_mdm" + mdm_replicates[k], mdm[k], {{"method", "MDM"}, {"row", "MDM"}});
    ReportOptions options;
    options.job_dir = dir + "/job";
    options.previews = false;
    auto summary = WriteReport(options);
    EXPECT_TRUE(summary.ok()) << summary.status().ToString();
    for (const ClaimCheck& c : summary->claims)
      if (c.claim == "MDT beats MDM") return c;
    return ClaimCheck{};
  };
  const ClaimCheck paired = report({"", "-s2", "-s3", "-s10"});
  EXPECT_EQ(paired.verdict, "holds") << paired.detail;
  EXPECT_NE(paired.detail.find("of the 4 per-seed differences (1.50, 2.00, 1.20, 1.40; unpaired"),
            std::string::npos)
      << paired.detail;
  // The MDM's fourth run is another seed's (11): nothing pairs, and the seeds' spread decides
  // nothing.
  const ClaimCheck unpaired = report({"", "-s2", "-s3", "-s11"});
  EXPECT_EQ(unpaired.verdict, "not decided: the difference is within two standard errors")
      << unpaired.detail;
  EXPECT_EQ(unpaired.detail.find("per-seed"), std::string::npos) << unpaired.detail;
  fs::remove_all(dir);
}

TEST(Papers, TheBuiltInPapersAreBothPapersTables) {
  auto papers = LoadPapers();
  ASSERT_TRUE(papers.ok()) << papers.status().ToString();
  ASSERT_EQ(papers->size(), 2u);
  const Paper& edit = (*papers)[0];
  EXPECT_EQ(edit.name, "SimMotionEdit");
  EXPECT_EQ(edit.evaluation, "edit");
  EXPECT_EQ(edit.columns, (std::vector<std::string>{"R@1", "R@2", "R@3", "AvgR"}));
  ASSERT_EQ(edit.rows.size(), 6u);
  EXPECT_EQ(edit.claims.size(), 5u);
  const PaperRow* mdt = edit.Find("", "MDT (SimMotionEdit)");  // an older evaluation's method
  ASSERT_NE(mdt, nullptr);
  EXPECT_EQ(mdt->row, "SimMotionEdit (MDT)");
  EXPECT_EQ(mdt->values, (std::vector<double>{70.62, 82.92, 88.12, 2.38}));
  EXPECT_EQ(edit.Find("TMED", "MDT (SimMotionEdit)")->row, "TMED");  // a named row comes first
  EXPECT_EQ(edit.Find("", "an unknown method"), nullptr);
  const Paper& sinc = (*papers)[1];
  EXPECT_EQ(sinc.name, "SINC");
  EXPECT_EQ(sinc.evaluation, "generate");
  EXPECT_EQ(sinc.Find("", "sinc (+ synthetic, labels)")->values, (std::vector<double>{0.644}));
  EXPECT_EQ(sinc.metric.pointer, "/temos_score");
  EXPECT_EQ(sinc.claims.size(), 3u);
}

TEST(Papers, ErrorsNameTheFileAndTheField) {
  const std::string head = "paper: P\nevaluation: edit\ntitle: T\ncolumns: [R@1]\n";
  const auto error = [](const std::string& text) {
    auto p = ParsePaper(text, "p.yaml");
    return p.ok() ? std::string("ok") : p.status().message();
  };
  EXPECT_EQ(error(head + "rows: [{row: A, values: [1]}]\n"), "ok");
  EXPECT_EQ(error(head + "rows: [{row: A, values: [1, 2]}]\n"),
            "p.yaml: rows[0]: 'values' must list one number per column (1)");
  EXPECT_EQ(error("paper: P\nevaluation: score\ntitle: T\nrows: []\n"),
            "p.yaml: 'evaluation' must be edit or generate");
  EXPECT_EQ(error(head + "rows: [{row: A}]\nclaims: [{claim: c, better: A, worse: B}]\n"),
            "p.yaml: claims need a 'metric'");
  EXPECT_EQ(error(head + "rows: [{row: A}]\nmetric: {name: m, pointer: /m}\n"
                         "claims: [{claim: c, better: A, worse: B}]\n"),
            "p.yaml: claims[0]: 'B' is not a row of the paper");
  EXPECT_EQ(error(head + "rows: [{values: [1]}]\n"), "p.yaml: rows[0]: 'row' must be a string");
  EXPECT_EQ(error(head + "rows: [{row: A}]\nmetric: {name: m, pointer: /m, higher_is_better: 1}\n"),
            "p.yaml: metric: 'higher_is_better' must be true or false");
  EXPECT_NE(error("paper: [\n").find("p.yaml:"), std::string::npos);
}

// A third paper: one YAML file, given to the report, adds its table and its claims; an evaluation
// names its row in it; a file of a built-in paper's name replaces that paper.
// How the report tabulates each evaluation kind is data too (configs/evaluations/*.yaml): the
// built-in layouts parse, and a broken one names its file and field.
TEST(Papers, EvaluationLayoutsAreDataAndErrorsNameTheirField) {
  std::vector<std::string> kinds;
  for (const EvaluationLayout& layout : EvaluationLayouts()) kinds.push_back(layout.evaluation);
  EXPECT_EQ(kinds, (std::vector<std::string>{"edit", "generate"}));
  const EvaluationLayout& edit = EvaluationLayouts()[0];
  EXPECT_EQ(edit.protocol_of, "generated_to_target");
  EXPECT_EQ(edit.columns.front().pointer, "/generated_to_target/{protocol}/R@1");
  EXPECT_EQ(edit.yardsticks.front(),
            (std::pair<std::string, std::string>{"copy", "source as the edit (copy)"}));
  const auto error = [](const std::string& text) {
    auto layout = ParseEvaluationLayout(text, "e.yaml");
    return layout.ok() ? std::string("ok") : layout.status().message();
  };
  const std::string head = "evaluation: e\nintro: I\ncaption: C\n";
  EXPECT_EQ(error(head + "columns: [{group: g, name: n, pointer: /x}]\n"), "ok");
  EXPECT_EQ(error(head + "columns: []\n"), "e.yaml: 'columns' must be a non-empty list");
  EXPECT_EQ(error(head + "columns: [{group: g, name: n, pointer: x}]\n"),
            "e.yaml: columns[0]: 'pointer' must be a JSON pointer (/a/b)");
  EXPECT_EQ(error(head + "columns: [{group: g, name: n, pointer: /x, decimals: two}]\n"),
            "e.yaml: columns[0]: 'decimals' must be an integer");
  EXPECT_EQ(error(head + "protocol_of: k\ncolumns: [{group: g, name: n, pointer: /x}]\n"),
            "e.yaml: 'protocol_of' needs 'protocols' (batches, all)");
  EXPECT_EQ(
      error(head +
            "columns: [{group: g, name: n, pointer: /x}]\n"
            "more: [{caption: M, when: always, columns: [{group: g, name: n, pointer: /y}]}]\n"),
      "e.yaml: more[0]: 'when' must be batches (or absent)");
  // What the report draws beside the tables is the layout's too: plausibility, preview, evaluators.
  EXPECT_EQ(edit.legacy_key, "generated_to_target");
  ASSERT_TRUE(edit.plausibility && edit.preview);
  EXPECT_EQ(edit.plausibility->truth_side, "target");
  EXPECT_EQ(edit.preview->method_role, "edited");
  ASSERT_EQ(edit.evaluators.size(), 1u);
  EXPECT_EQ(edit.evaluators[0].pointers, std::vector<std::string>{"/target_to_source/batches"});
  const std::string cols = "columns: [{group: g, name: n, pointer: /x}]\n";
  EXPECT_EQ(error(head + cols + "evaluators: [{label: L, form: table, pointers: [/q]}]\n"),
            "e.yaml: evaluators[0]: 'form' must be text_motion, motion_motion or score_pair");
  EXPECT_EQ(error(head + cols + "evaluators: [{label: L, form: score_pair, pointers: [/q]}]\n"),
            "e.yaml: evaluators[0]: 'pointers' must list 2 JSON pointer(s) for form score_pair");
  EXPECT_EQ(error(head + cols + "plausibility: {truth: {side: t}, generated: g}\n"),
            "e.yaml: plausibility.truth: 'row' must be a string");
  EXPECT_EQ(error(head + cols +
                  "preview: {references: [{role: r}], method_role: m, alt: A, "
                  "caption: C}\n"),
            "e.yaml: preview.references[0]: 'label' must be a string");
}

// In a job, an untrained evaluation with untrained_of is the yardstick of those rows only; the one
// without is every other row's. Both show as rows; neither stands in for a trained row.
TEST(Claims, AnUntrainedRowOfItsOwnJudgesTheRowsItNames) {
  namespace fs = std::filesystem;
  const std::string dir = ::testing::TempDir() + "/own_untrained";
  fs::remove_all(dir);
  const auto eval = [&](const std::string& stage, double r1, const nlohmann::json& extra) {
    WriteEditEval(dir + "/job", stage, r1, extra);
  };
  eval("eval_untrained", 66, {{"method", "untrained MDT"}, {"yardstick", "untrained"}});
  eval("eval_mdm_untrained", 3,
       {{"method", "untrained MDM"}, {"yardstick", "untrained"}, {"untrained_of", {"MDM"}}});
  const double mdt[] = {69, 70, 71}, mdm[] = {14, 15, 16};
  for (int k = 0; k < 3; ++k) {
    const std::string replicate = k == 0 ? "" : "-s" + std::to_string(k + 1);
    eval("eval_mdt" + replicate, mdt[k], {{"method", "MDT"}, {"row", "SimMotionEdit (MDT)"}});
    eval("eval_mdm" + replicate, mdm[k], {{"method", "MDM"}, {"row", "MDM"}});
  }
  ReportOptions options;
  options.job_dir = dir + "/job";
  options.previews = false;
  auto summary = WriteReport(options);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  const auto claim = [&](const std::string& name) {
    for (const ClaimCheck& c : summary->claims)
      if (c.claim == name) return c;
    return ClaimCheck{};
  };
  EXPECT_EQ(claim("MDT beats MDM").verdict, "holds") << claim("MDT beats MDM").detail;
  EXPECT_NE(claim("MDT beats MDM").detail.find("MDM's untrained row (untrained MDM) 3.00"),
            std::string::npos)
      << claim("MDT beats MDM").detail;
  // TMED has no row in this job; the MDT's own claims against the general row are unchanged.
  EXPECT_EQ(claim("MDT beats TMED").verdict, "not measured");
  auto html = ReadFile(dir + "/job/report.html");
  ASSERT_TRUE(html.ok());
  EXPECT_NE(html->find("<td>untrained MDT</td>"), std::string::npos);
  EXPECT_NE(html->find("<td>untrained MDM</td>"), std::string::npos);
  fs::remove_all(dir);
}

TEST(Papers, AThirdPapersTableIsOneFile) {
  namespace fs = std::filesystem;
  const std::string dir = ::testing::TempDir() + "/third_paper";
  fs::remove_all(dir);
  const auto eval = [&](const std::string& stage, const nlohmann::json& extra) {
    nlohmann::json m = {{"method", stage},
                        {"motions", 4},
                        {"generated_to_target", {{"all", {{"R@1", 50.0}, {"queries", 4}}}}},
                        {"generated_to_source", {{"all", {{"R@1", 25.0}}}}}};
    m.update(extra);
    fs::create_directories(dir + "/job/" + stage + "/task-00000");
    ASSERT_TRUE(WriteFileAtomic(dir + "/job/" + stage + "/task-00000/metrics.json", m.dump()).ok());
  };
  eval("eval_a", {{"row", "Editor A"}});
  eval("eval_b",
       {{"row", "Editor B"},
        {"evaluation", "edit"},  // eval_a has no such key: read by the layout's legacy_key
        {"method", "tmed"},
        {"generated_to_target", {{"all", {{"R@1", 40.0}, {"queries", 4}}}}}});
  // The "evaluation" key decides the kind, whatever other keys the metrics hold.
  eval("eval_c", {{"evaluation", "generate"}, {"temos_score", 0.5}});
  ASSERT_TRUE(
      WriteFileAtomic(dir + "/third.yaml",
                      "paper: Third\nevaluation: edit\ntitle: A third paper's table\n"
                      "columns: [R@1]\nrows:\n  - {row: Editor B, values: [40.5]}\n"
                      "  - {row: Editor A, values: [60.25]}\n"
                      "metric: {name: R@1, pointer: \"/generated_to_target/{protocol}/R@1\"}\n"
                      "claims: [{claim: A beats B, better: Editor A, worse: Editor B}]\n")
          .ok());
  ReportOptions options;
  options.job_dir = dir + "/job";
  options.previews = false;
  options.papers = {dir + "/third.yaml"};
  auto summary = WriteReport(options);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_EQ(summary->methods, (std::map<std::string, int>{{"edit", 2}, {"generate", 1}}));
  auto html = ReadFile(dir + "/job/report.html");
  ASSERT_TRUE(html.ok());
  EXPECT_NE(html->find("<h2>A third paper's table</h2>"), std::string::npos) << *html;
  // Its rows in its order, its numbers beside them; the same run is TMED in SimMotionEdit's table.
  const size_t b = html->find("<td>Editor B</td>"), a = html->find("<td>Editor A</td>");
  ASSERT_NE(b, std::string::npos);
  ASSERT_NE(a, std::string::npos);
  EXPECT_LT(b, a);
  EXPECT_NE(html->find("<td class=\"paper\">60.25</td>"), std::string::npos);
  EXPECT_NE(html->find("<td>TMED</td>"), std::string::npos);
  ASSERT_EQ(summary->claims.size(), 5u + 3u + 1u);
  const ClaimCheck& third = summary->claims.back();
  EXPECT_EQ(third.paper, "Third");
  EXPECT_EQ(third.verdict, "not decidable: fewer than 3 seeds (the means go the claimed way)");
  EXPECT_NE(third.detail.find("R@1: 50.00 (n=1) vs 40.00 (n=1)"), std::string::npos)
      << third.detail;
  // The same paper name replaces the built-in table.
  ASSERT_TRUE(
      WriteFileAtomic(dir + "/sinc.yaml", "paper: SINC\nevaluation: generate\ntitle: S\nrows: []\n")
          .ok());
  auto papers = LoadPapers({dir + "/sinc.yaml"});
  ASSERT_TRUE(papers.ok()) << papers.status().ToString();
  ASSERT_EQ(papers->size(), 2u);
  EXPECT_TRUE((*papers)[1].rows.empty());
  fs::remove_all(dir);
}

// The training table's time to a retrieval quality: the seconds of the first validation at or
// above the bar, not of a later one or of the best.
TEST(Training, SecondsToReachIsTheFirstValidationAtTheBar) {
  const std::vector<double> r1 = {3.1, 25.0, 40.0, 38.5, 62.5};
  const std::vector<double> seconds = {60, 120, 180, 240, 300};
  EXPECT_EQ(SecondsToReach(r1, seconds, 40), std::optional<double>(180));
  EXPECT_EQ(SecondsToReach(r1, seconds, 50), std::optional<double>(300));
  EXPECT_EQ(SecondsToReach(r1, seconds, 3), std::optional<double>(60));
  EXPECT_FALSE(SecondsToReach(r1, seconds, 70).has_value());
  EXPECT_FALSE(SecondsToReach({}, {}, 40).has_value());
  EXPECT_FALSE(SecondsToReach(r1, {60, 120}, 40).has_value());  // columns of different lengths
}

// The training table reads each stage's losses.csv and val_losses.csv by column name: a row is
// used where the columns it needs are numbers (a validation whose seconds are missing still gives
// its loss, not a time), and an older val_losses.csv without R@1 or seconds leaves that cell empty.
TEST(Training, TheTableReadsTheLoggedColumnsByNameRowByRow) {
  namespace fs = std::filesystem;
  const std::string dir = ::testing::TempDir() + "/training_table", job = dir + "/job";
  fs::remove_all(dir);
  const auto write = [&](const std::string& stage, const std::string& file,
                         const std::string& text) {
    fs::create_directories(job + "/" + stage + "/task-00000");
    ASSERT_TRUE(WriteFileAtomic(job + "/" + stage + "/task-00000/" + file, text).ok());
  };
  write("evaluator", "losses.csv",
        "step,epoch,lr,loss,retrieval_r1\n0,0,1e-05,1.5,3.1\n1,0,2e-05,1.25,6.2\n");
  write("evaluator", "val_losses.csv",
        "step,val_loss,seconds,val_retrieval_r1\n249,0.4,60,25\n499,0.33,120,40\n"
        "749,0.2,,45\n999,0.28,240,62.5\n1249,oops,300,70\n");
  write("old", "losses.csv", "step,epoch,lr,loss\n0,0,1e-05,2\n1,0,2e-05,1.75\n");
  write("old", "val_losses.csv", "step,val_loss\n1,0.9\n");
  ReportOptions options;
  options.job_dir = job;
  options.previews = false;
  auto summary = WriteReport(options);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_EQ(summary->train_stages, 2);
  auto html = ReadFile(summary->path);
  ASSERT_TRUE(html.ok());
  const auto row = [&](const std::string& stage) {
    const size_t at = html->find("<tr><td>" + stage + "</td>");
    return at == std::string::npos ? std::string() : html->substr(at, html->find("</tr>", at) - at);
  };
  // Held-out loss: last 0.28 (the row with `oops` has no loss), best 0.2 at step 750 (its seconds
  // missing); R@1: last 70 (that row's R@1 and seconds are numbers), first at 40 after 120 s.
  const std::string evaluator = row("evaluator");
  EXPECT_NE(evaluator.find("<td>1.5000</td><td>1.2500</td><td>0.2800</td><td>0.2000 (750)</td>"),
            std::string::npos)
      << evaluator;
  EXPECT_NE(evaluator.find("<td>70.0 (2.0 min)</td>"), std::string::npos) << evaluator;
  const std::string old = row("old");
  EXPECT_NE(old.find("<td>0.9000</td><td>0.9000 (2)</td><td>&ndash;</td>"), std::string::npos)
      << old;
}

}  // namespace
}  // namespace motionpipe::report
