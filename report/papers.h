// The papers' tables as data: each configs/papers/*.yaml names a paper's table (which evaluations
// it holds, its rows with their published numbers) and the claims the report checks. The files are
// built in; a user's files add papers or replace one of the same name. The engine names no paper:
// a third paper's table is a new file.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe::report {

struct PaperRow {
  std::string row;                   // as the paper names it; an evaluation's params.row
  std::vector<std::string> methods;  // lower-case `method` strings of evaluations without a row
  std::vector<double> values;        // the published numbers, one per Paper::columns
};

struct PaperClaim {
  std::string claim;
  std::string better, worse;  // rows of the paper
};

struct PaperMetric {    // what the claims compare
  std::string name;     // as printed
  std::string pointer;  // JSON pointer into an evaluation's metrics; {protocol} is
                        // "batches" or "all"
  bool higher_is_better = true;
  int decimals = 2;
};

struct Paper {
  std::string name;        // "SimMotionEdit"
  std::string evaluation;  // an evaluation kind with a layout: "edit" (eval_edit), "generate"
                           // (eval_generate)
  std::string title;       // the table's heading
  std::string note;        // appended to the table's description; may be empty
  std::vector<std::string> columns;  // the published columns
  int decimals = 2;
  std::vector<PaperRow> rows;
  PaperMetric metric;
  std::vector<PaperClaim> claims;
  std::string origin;  // the file it came from

  // The row an evaluation belongs to: its params.row if it names one of ours, else the row whose
  // `methods` hold its method string (any case); nullptr when neither.
  const PaperRow* Find(const std::string& row, const std::string& method) const;
};

// How the report tabulates one evaluation kind's metrics (configs/evaluations/<kind>.yaml, built
// in): the columns a paper's rows are drawn in, the table's description, and tables drawn once for
// the kind. In pointers and texts, {protocol} is "batches" or "all" (see `protocol_of`).
struct LayoutColumn {
  std::string group, name, pointer;
  int decimals = 2;
  bool higher_is_better = true;
  bool bold_best = true;
};

struct LayoutTable {
  std::string caption;
  std::string when;             // "" (always) or "batches" (only when the main table is in batches)
  bool with_yardsticks = true;  // the yardstick rows too, or only the methods
  std::vector<LayoutColumn> columns;
};

// Texts of a layout (intro, captions, labels, notes) are HTML.
// A row of the report's "Evaluator quality" table, read from the first evaluation run that has
// pointers[0]. form: "text_motion" (an object with motions, text_to_motion and motion_to_text
// retrieval scores), "motion_motion" (retrieval scores of motions among motions; the run's
// /motions), "score_pair" (two scores, pointers[0] / pointers[1], with `note`).
struct EvaluatorRow {
  std::string label, form, note;
  std::vector<std::string> pointers;
};

// The physical-plausibility rows of an evaluation kind: the ground truth's side
// (metrics /plausibility/<truth_side>, from the first method), then each method's generated side.
struct PlausibilityLayout {
  std::string truth_side, truth_row, generated_side;
};

// The preview of an evaluation kind: the first evaluated example's reference motions (roles of
// preview.npz), then each method's motion of `method_role`, in one GIF; `caption` with {text} (the
// first reference's text that has `text: true`).
struct PreviewLayout {
  struct Reference {
    std::string role, label;
    bool text = false;
  };
  std::vector<Reference> references;
  std::string method_role, alt, caption;
};

struct EvaluationLayout {
  std::string evaluation;   // the papers' `evaluation:` value, e.g. "edit"
  std::string legacy_key;   // metrics.json written without "evaluation" are this kind's when they
                            // hold this key
  std::string protocol_of;  // metrics key whose batches decide {protocol}; "" = always "all"
  std::vector<std::pair<std::string, std::string>> protocols;  // {protocol} -> {protocol_text}
  std::string intro;  // HTML; {protocol_text}, {batch}, {note}
  std::string caption;
  std::vector<LayoutColumn> columns;
  std::vector<LayoutTable> more;
  // The reference rows an evaluation scores beside its method (metrics "yardsticks": key), each
  // with the row name the tables give it.
  std::vector<std::pair<std::string, std::string>> yardsticks;
  std::optional<PlausibilityLayout> plausibility;
  std::optional<PreviewLayout> preview;
  std::vector<EvaluatorRow> evaluators;
  std::string origin;
};

Result<EvaluationLayout> ParseEvaluationLayout(const std::string& yaml_text,
                                               const std::string& origin);

// The built-in layouts (configs/evaluations at build time), one per evaluation kind.
const std::vector<EvaluationLayout>& EvaluationLayouts();

// One paper file; every error names `origin` and the field.
Result<Paper> ParsePaper(const std::string& yaml_text, const std::string& origin);

// The built-in papers (configs/papers at build time), then each file of `files`: a paper of a
// name already loaded replaces it, a new one is added.
Result<std::vector<Paper>> LoadPapers(const std::vector<std::string>& files = {});

}  // namespace motionpipe::report
