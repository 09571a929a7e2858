#include "report.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <set>
#include <sstream>

#include "metric_history.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/render/chart.h"
#include "motionpipe/render/motion_render.h"
#include "papers.h"

namespace motionpipe::report {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// ---- what the job directory holds
// -----------------------------------------------------------------

struct Run {
  std::string stage;  // e.g. eval_edit_mdt-s2
  std::string dir;    // its task-00000
  json metrics;
};

struct Method {
  std::string name;       // the `method` string
  std::string row;        // the paper row the evaluation names (params.row), or empty
  std::string paper_row;  // the row of the paper that orders the table; empty when it has none
  int paper_index = 1000;
  std::vector<Run> runs;  // seed replicates, replicate 1 first
  bool yardstick =
      false;  // a reference row (copy, ground truth, shuffled, untrained): never "best"
  bool untrained = false;  // the untrained model's row (eval param yardstick: untrained)
  // The paper rows an untrained row is the yardstick of (eval param untrained_of); empty: of
  // every row that has no untrained row of its own.
  std::vector<std::string> untrained_of;
};

// The yardstick rows an evaluation computed beside its method (metrics "yardsticks": key -> the
// same metrics as a method's), taken from the first method that has them: every evaluation of a job
// scores the same test split, and its seed replicates give the rows' spread.
std::vector<Method> YardstickRows(const std::vector<const Method*>& methods,
                                  const std::vector<std::pair<std::string, std::string>>& keys) {
  for (const Method* m : methods) {
    if (m->untrained || m->runs.empty() || !m->runs.front().metrics.contains("yardsticks"))
      continue;
    std::vector<Method> out;
    for (const auto& [key, label] : keys) {
      if (!m->runs.front().metrics["yardsticks"].contains(key)) continue;  // an older job's
      Method row;
      row.name = label;
      row.yardstick = true;
      for (const Run& r : m->runs) {
        json metrics = r.metrics["yardsticks"].value(key, json::object());
        metrics["motions"] = r.metrics.value("motions", 0);
        row.runs.push_back({r.stage, r.dir, metrics});
      }
      out.push_back(std::move(row));
    }
    return out;
  }
  return {};
}

// The job's general untrained row: the untrained row that names no rows of its own (else the
// first).
const Method* UntrainedRow(const std::vector<const Method*>& methods) {
  const Method* first = nullptr;
  for (const Method* m : methods) {
    if (!m->untrained) continue;
    if (m->untrained_of.empty()) return m;
    if (!first) first = m;
  }
  return first;
}

// The untrained row a paper row is judged against: its own (untrained_of names it), else the
// general one.
const Method* UntrainedFor(const std::vector<const Method*>& methods, const std::string& row) {
  for (const Method* m : methods) {
    if (m->untrained &&
        std::find(m->untrained_of.begin(), m->untrained_of.end(), row) != m->untrained_of.end())
      return m;
  }
  for (const Method* m : methods) {
    if (m->untrained && m->untrained_of.empty()) return m;
  }
  return nullptr;
}

std::string RowName(const Method& m) { return m.paper_row.empty() ? m.name : m.paper_row; }

struct TrainCurve {
  std::string stage;
  std::vector<double> steps, losses;
  std::vector<double> val_steps,
      val_losses;  // the held-out split's loss (val_losses.csv), if validated
  // Where the model logs it (TEMOS, SINC, TMR): the held-out text->motion R@1 within batches, and
  // the training seconds at each validation (val_losses.csv's val_retrieval_r1 and seconds).
  std::vector<double> val_r1, val_seconds;
  double seconds = 0;
};

std::string BaseStage(const std::string& stage) {
  static const std::regex kReplicate("(.*)-s[0-9]+");
  std::smatch match;
  return std::regex_match(stage, match, kReplicate) ? match[1].str() : stage;
}

std::optional<json> ReadJson(const std::string& path) {
  auto text = ReadFile(path);
  if (!text.ok()) return std::nullopt;
  json value = json::parse(*text, nullptr, false);
  if (value.is_discarded()) return std::nullopt;
  return value;
}

// A CSV of numbers under a header (losses.csv, val_losses.csv), read once. A cell that is missing
// (a row shorter than the header) or not a number reads NaN.
struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<double>> rows;

  // The columns `names`, in that order, over the rows where each of them is a finite number;
  // nullopt when a name is not in the header or no row has them all.
  std::optional<std::vector<std::vector<double>>> Columns(
      const std::vector<std::string>& names) const {
    std::vector<size_t> at;
    for (const std::string& name : names) {
      const auto it = std::find(header.begin(), header.end(), name);
      if (it == header.end()) return std::nullopt;
      at.push_back(static_cast<size_t>(it - header.begin()));
    }
    std::vector<std::vector<double>> out(names.size());
    for (const auto& row : rows) {
      if (std::any_of(at.begin(), at.end(),
                      [&](size_t k) { return k >= row.size() || !std::isfinite(row[k]); }))
        continue;
      for (size_t c = 0; c < at.size(); ++c) out[c].push_back(row[at[c]]);
    }
    if (out.front().empty()) return std::nullopt;
    return out;
  }
};

std::optional<CsvTable> ReadCsvTable(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  if (!in || !std::getline(in, line)) return std::nullopt;
  CsvTable table;
  std::stringstream hs(line);
  for (std::string cell; std::getline(hs, cell, ',');) table.header.push_back(cell);
  while (std::getline(in, line)) {
    std::vector<double> row;
    std::stringstream ls(line);
    for (std::string cell; std::getline(ls, cell, ',');) {
      char* end = nullptr;
      const double value = std::strtod(cell.c_str(), &end);
      row.push_back(end != cell.c_str() ? value : std::numeric_limits<double>::quiet_NaN());
    }
    table.rows.push_back(std::move(row));
  }
  return table;
}

// ---- statistics over seeds
// ------------------------------------------------------------------------

struct Stat {
  double mean = 0, sd = 0;
  int n = 0;
};

Stat Summarize(const std::vector<double>& values) {
  Stat s;
  s.n = static_cast<int>(values.size());
  if (s.n == 0) return s;
  for (double v : values) s.mean += v;
  s.mean /= s.n;
  if (s.n > 1) {
    double ss = 0;
    for (double v : values) ss += (v - s.mean) * (v - s.mean);
    s.sd = std::sqrt(ss / (s.n - 1));  // sample standard deviation
  }
  return s;
}

// A metric by JSON pointer ("/generated_to_target/batches/R@1") over the method's runs.
std::vector<double> Values(const Method& m, const std::string& pointer) {
  std::vector<double> values;
  for (const Run& r : m.runs) {
    const json::json_pointer p(pointer);
    if (r.metrics.contains(p) && r.metrics[p].is_number())
      values.push_back(r.metrics[p].get<double>());
  }
  return values;
}

Stat Collect(const Method& m, const std::string& pointer) { return Summarize(Values(m, pointer)); }

// A run's replicate k of its stage's `seeds: N` (the stage is name-sk for k > 1, pipeline.cc).
int Replicate(const Run& run) {
  const size_t at = run.stage.rfind("-s");
  if (at == std::string::npos || at + 2 >= run.stage.size()) return 1;
  int k = 0;
  for (size_t i = at + 2; i < run.stage.size(); ++i) {
    if (!std::isdigit(static_cast<unsigned char>(run.stage[i]))) return 1;
    k = k * 10 + (run.stage[i] - '0');
    if (k > 1000) return 1;
  }
  return k;
}

// A metric by JSON pointer over the method's runs, by replicate.
std::map<int, double> ValuesByReplicate(const Method& m, const std::string& pointer) {
  std::map<int, double> values;
  const json::json_pointer p(pointer);
  for (const Run& r : m.runs) {
    if (r.metrics.contains(p) && r.metrics[p].is_number())
      values[Replicate(r)] = r.metrics[p].get<double>();
  }
  return values;
}

std::string Format(double value, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

std::string Escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// ---- HTML tables
// ----------------------------------------------------------------------------------

using Column = LayoutColumn;

struct PaperCell {
  std::vector<std::optional<double>> values;  // per paper column
};

// Methods as rows; each cell "mean ± sd" over the seeds; the best mean of each column in bold.
std::string MetricTable(const std::string& caption, const std::vector<const Method*>& methods,
                        const std::vector<Column>& columns,
                        const std::vector<std::string>& paper_columns,
                        const std::vector<PaperCell>& paper, int paper_decimals) {
  std::vector<std::vector<Stat>> stats(methods.size());
  for (size_t m = 0; m < methods.size(); ++m) {
    for (const Column& c : columns) stats[m].push_back(Collect(*methods[m], c.pointer));
  }
  std::vector<int> best(columns.size(), -1);
  for (size_t c = 0; c < columns.size(); ++c) {
    for (size_t m = 0; m < methods.size(); ++m) {
      if (stats[m][c].n == 0 || methods[m]->yardstick) continue;
      const int b = best[c];
      if (b < 0 || (columns[c].higher_is_better
                        ? stats[m][c].mean > stats[static_cast<size_t>(b)][c].mean
                        : stats[m][c].mean < stats[static_cast<size_t>(b)][c].mean)) {
        best[c] = static_cast<int>(m);
      }
    }
  }
  std::ostringstream html;
  html << "<table>\n<caption>" << caption
       << "</caption>\n<thead><tr><th rowspan=\"2\">Method</th><th rowspan=\"2\">seeds</th>";
  // Group header.
  for (size_t c = 0; c < columns.size();) {
    size_t span = 1;
    while (c + span < columns.size() && columns[c + span].group == columns[c].group) ++span;
    html << "<th colspan=\"" << span << "\">" << Escape(columns[c].group) << "</th>";
    c += span;
  }
  if (!paper_columns.empty())
    html << "<th class=\"paper\" colspan=\"" << paper_columns.size() << "\">paper</th>";
  html << "</tr>\n<tr>";
  for (const Column& c : columns)
    html << "<th>" << Escape(c.name) << (c.higher_is_better ? " &uarr;" : " &darr;") << "</th>";
  for (const std::string& p : paper_columns) html << "<th class=\"paper\">" << Escape(p) << "</th>";
  html << "</tr></thead>\n<tbody>\n";
  for (size_t m = 0; m < methods.size(); ++m) {
    const Method& method = *methods[m];
    const std::string name = Escape(RowName(method));
    html << "<tr" << (method.yardstick ? " class=\"yardstick\"" : "") << "><td>"
         << (method.yardstick ? "<i>" + name + "</i>" : name) << "</td><td>" << method.runs.size()
         << "</td>";
    for (size_t c = 0; c < columns.size(); ++c) {
      const Stat& s = stats[m][c];
      if (s.n == 0) {
        html << "<td>&ndash;</td>";
        continue;
      }
      std::string cell = Format(s.mean, columns[c].decimals);
      if (s.n > 1)
        cell += " <span class=\"sd\">&plusmn; " + Format(s.sd, columns[c].decimals) + "</span>";
      const bool bold =
          columns[c].bold_best && best[c] == static_cast<int>(m) && methods.size() > 1;
      html << "<td>" << (bold ? "<b>" + cell + "</b>" : cell) << "</td>";
    }
    for (size_t p = 0; p < paper_columns.size(); ++p) {
      const auto& value =
          m < paper.size() && p < paper[m].values.size() ? paper[m].values[p] : std::nullopt;
      html << "<td class=\"paper\">" << (value ? Format(*value, paper_decimals) : "&ndash;")
           << "</td>";
    }
    html << "</tr>\n";
  }
  html << "</tbody></table>\n";
  return html.str();
}

// Whether every run was scored in batches by `key` (e.g. generated_to_target): the batch protocol
// needs at least one full batch of test motions; with fewer, the tables and claims use the whole
// set.
bool AllBatched(const std::vector<const Method*>& methods, const std::string& key) {
  for (const Method* m : methods) {
    for (const Run& r : m->runs) {
      if (r.metrics.value(json::json_pointer("/" + key + "/batches/queries"), 0) <= 0) return false;
    }
  }
  return true;
}

// ---- claims
// ---------------------------------------------------------------------------------------

std::string StatText(const Stat& s, int decimals) {
  return Format(s.mean, decimals) + (s.n > 1 ? " ± " + Format(s.sd, decimals) : "") +
         " (n=" + std::to_string(s.n) + ")";
}

// A paper's claim "better beats worse" on `pointer` (issue 15's calibration): not decidable while a
// compared model does not beat the untrained row, or with fewer than 3 seeds a side; it holds when
// the difference of the means beats two standard errors, does not hold when the reverse does. The
// runs pair by seed when both rows hold the same 3+ replicates (DecideClaim).
ClaimCheck Compare(const std::string& paper, const std::string& claim, const Method* better,
                   const Method* worse, const Method* better_untrained,
                   const Method* worse_untrained, const std::string& pointer,
                   const std::string& metric_name, bool higher_is_better, int decimals) {
  ClaimCheck out{paper, claim, "not measured", ""};
  if (!better || !worse) {
    out.detail = "a method of the comparison is not in this job";
    return out;
  }
  std::vector<double> a_values = Values(*better, pointer), b_values = Values(*worse, pointer);
  // Paired by seed when both sides hold the same 3+ replicates (DecideClaim).
  const std::map<int, double> a_seeds = ValuesByReplicate(*better, pointer),
                              b_seeds = ValuesByReplicate(*worse, pointer);
  bool paired = a_seeds.size() >= 3 && a_seeds.size() == a_values.size() &&
                a_seeds.size() == b_seeds.size() && b_seeds.size() == b_values.size();
  for (auto a = a_seeds.begin(), b = b_seeds.begin(); paired && a != a_seeds.end(); ++a, ++b)
    paired = a->first == b->first;
  if (paired) {
    a_values.clear();
    b_values.clear();
    for (const auto& [k, v] : a_seeds) a_values.push_back(v);
    for (const auto& [k, v] : b_seeds) b_values.push_back(v);
  }
  const auto untrained_values = [&](const Method* u) {
    return u ? Values(*u, pointer) : std::vector<double>{};
  };
  const std::vector<double> u_values = untrained_values(better_untrained),
                            w_values = untrained_values(worse_untrained);
  if (a_values.empty() || b_values.empty()) {
    out.detail = "no " + metric_name + " for one of the methods";
    return out;
  }
  const Stat a = Summarize(a_values), b = Summarize(b_values);
  const double diff = higher_is_better ? a.mean - b.mean : b.mean - a.mean;
  out.detail = metric_name + ": " + StatText(a, decimals) + " vs " + StatText(b, decimals) +
               "; difference " + Format(diff, decimals) + ", 2 standard errors " +
               Format(TwoStandardErrors(a_values, b_values, paired), decimals);
  if (paired) {
    out.detail += " of the " + std::to_string(a.n) + " per-seed differences (";
    for (size_t k = 0; k < a_values.size(); ++k) {
      const double d = higher_is_better ? a_values[k] - b_values[k] : b_values[k] - a_values[k];
      out.detail += (k ? ", " : "") + Format(d, decimals);
    }
    out.detail +=
        "; unpaired, " + Format(TwoStandardErrors(a_values, b_values, false), decimals) + ")";
  }
  if (better_untrained == worse_untrained) {
    if (!u_values.empty()) out.detail += "; untrained " + StatText(Summarize(u_values), decimals);
  } else {
    const auto own = [&](const Method* side, const Method* u, const std::vector<double>& values) {
      if (!values.empty())
        out.detail += "; " + RowName(*side) + "'s untrained row (" + u->name + ") " +
                      StatText(Summarize(values), decimals);
    };
    own(better, better_untrained, u_values);
    own(worse, worse_untrained, w_values);
  }
  switch (DecideClaim(a_values, b_values, u_values, w_values, higher_is_better, paired)) {
    case ClaimVerdict::kHolds:
      out.verdict = "holds";
      break;
    case ClaimVerdict::kDoesNotHold:
      out.verdict = "does not hold";
      break;
    case ClaimVerdict::kWithinErrors:
      out.verdict = "not decided: the difference is within two standard errors";
      break;
    case ClaimVerdict::kFewSeeds:
      out.verdict = std::string("not decidable: fewer than 3 seeds (the means go ") +
                    (diff > 0 ? "the claimed way)" : "the other way)");
      break;
    case ClaimVerdict::kBetterNotTrained:
      out.verdict = "not decidable: " + RowName(*better) + " does not beat its untrained row";
      break;
    case ClaimVerdict::kWorseNotTrained:
      out.verdict = "not decidable: " + RowName(*worse) + " does not beat its untrained row";
      break;
  }
  return out;
}

// ---- the evaluators' own quality
// -------------------------------------------------------------------

// The first run of `methods` (the untrained row last) whose metrics hold `pointer`.
const json* FirstWith(const std::vector<const Method*>& methods, const std::string& pointer) {
  for (const bool untrained : {false, true}) {
    for (const Method* m : methods) {
      if (m->untrained != untrained) continue;
      for (const Run& r : m->runs) {
        if (r.metrics.contains(json::json_pointer(pointer))) return &r.metrics;
      }
    }
  }
  return nullptr;
}

// An evaluation kind's layout and its methods, ordered by the kind's first paper.
struct KindMethods {
  const EvaluationLayout* layout;
  std::vector<const Method*> methods;
};

// One row of the evaluator-quality table (EvaluatorRow's forms), or "" when no run measured it.
std::string EvaluatorTableRow(const EvaluatorRow& row, const std::vector<const Method*>& methods) {
  const json* m = FirstWith(methods, row.pointers[0]);
  if (!m) return "";
  const auto cell = [](const json& j, const char* key) {
    return j.contains(key) && j[key].is_number() ? Format(j[key].get<double>(), 1) : "&ndash;";
  };
  const json& q = m->at(json::json_pointer(row.pointers[0]));
  std::ostringstream out;
  out << "<tr><td>" << row.label << "</td><td>";  // HTML, as the layout's other texts
  if (row.form == "text_motion") {
    out << q.value("motions", 0) << "</td><td>" << cell(q["text_to_motion"], "R@1") << "</td><td>"
        << cell(q["text_to_motion"], "R@3") << "</td><td>" << cell(q["motion_to_text"], "R@1")
        << "</td><td>" << cell(q["motion_to_text"], "R@3") << "</td><td>"
        << q["text_to_motion"].value("queries", 0) << " queries in batches</td></tr>\n";
  } else if (row.form == "motion_motion") {
    out << m->value("motions", 0) << "</td><td>" << cell(q, "R@1") << "</td><td>" << cell(q, "R@3")
        << "</td><td>&ndash;</td><td>&ndash;</td><td>AvgR " << cell(q, "AvgR") << "</td></tr>\n";
  } else {  // score_pair
    const json::json_pointer second(row.pointers[1]);
    out << m->value("motions", 0) << "</td><td colspan=\"4\">" << Format(q.get<double>(), 3)
        << " / " << (m->contains(second) ? Format(m->at(second).get<double>(), 3) : "&ndash;")
        << "</td><td>" << row.note << "</td></tr>\n";
  }
  return out.str();
}

// What the evaluators can tell apart (issue 15), as each evaluation kind's layout lists it
// (`evaluators:`): retrieval of held-out texts and motions, and a score's range.
std::string EvaluatorSection(const std::vector<KindMethods>& kinds, int* tables) {
  std::string rows;
  for (const KindMethods& kind : kinds) {
    for (const EvaluatorRow& row : kind.layout->evaluators)
      rows += EvaluatorTableRow(row, kind.methods);
  }
  if (rows.empty()) return "";
  ++*tables;
  return "<h2>The evaluators</h2>\n<p>A score is only as good as the evaluator behind it: what the "
         "evaluators tell apart on the "
         "held-out test split, measured in this job (R@k in "
         "percent).</p>\n<table>\n<caption>Evaluator quality</caption>\n<thead><tr>"
         "<th>evaluator and test set</th><th>motions</th><th>text→motion R@1</th><th>text→motion "
         "R@3</th><th>motion→text R@1</th>"
         "<th>motion→text R@3</th><th></th></tr></thead>\n<tbody>\n" +
         rows + "</tbody></table>\n";
}

// ---- pictures
// -------------------------------------------------------------------------------------

std::string DataUri(const std::string& mime, const std::string& bytes) {
  return "data:" + mime + ";base64," + Base64(bytes);
}

std::string ImgTag(const std::string& mime, const std::string& bytes, const std::string& alt,
                   int* images) {
  ++*images;
  return "<img alt=\"" + Escape(alt) + "\" src=\"" + DataUri(mime, bytes) + "\">";
}

// One loss panel per training (replicates overlaid).
std::string CurvesPng(const std::string& title, const std::vector<const TrainCurve*>& curves) {
  render::Image image(420, 260);
  render::Panel panel(&image, 0, 0, 420, 260);
  double x_max = 1, y_min = 1e300, y_max = -1e300;
  for (const TrainCurve* c : curves) {
    x_max = std::max(x_max, c->steps.back());
    for (double v : c->losses) y_min = std::min(y_min, v), y_max = std::max(y_max, v);
    for (double v : c->val_losses) y_min = std::min(y_min, v), y_max = std::max(y_max, v);
  }
  if (y_max <= y_min) y_max = y_min + 1;
  panel.SetTitle(title);
  panel.SetLabels("step", "loss");
  panel.SetLimits(0, x_max, std::min(0.0, y_min), y_max * 1.05);
  panel.DrawAxes();
  std::vector<std::pair<std::string, render::Color>> legend;
  for (size_t k = 0; k < curves.size(); ++k) {
    const render::Color colour = render::kPalette[k % 8];
    panel.LinePlot(curves[k]->steps, curves[k]->losses, colour, 1.5);
    legend.push_back({curves[k]->stage, colour});
    if (!curves[k]->val_steps.empty()) {  // the held-out loss, thick, in the next colour
      const render::Color val_colour = render::kPalette[(k + curves.size()) % 8];
      panel.LinePlot(curves[k]->val_steps, curves[k]->val_losses, val_colour, 3);
      legend.push_back({curves[k]->stage + " (held-out)", val_colour});
    }
  }
  if (legend.size() > 1) panel.Legend(legend);
  return image.EncodePng();
}

std::string HistoryPng(const std::string& metric,
                       const std::map<std::string, std::vector<double>>& by_method) {
  render::Image image(520, 280);
  render::Panel panel(&image, 0, 0, 520, 280);
  double x_max = 1, y_min = 1e300, y_max = -1e300;
  for (const auto& [method, values] : by_method) {
    x_max = std::max(x_max, static_cast<double>(values.size()));
    for (double v : values) y_min = std::min(y_min, v), y_max = std::max(y_max, v);
  }
  if (y_max <= y_min) y_max = y_min + 1, y_min -= 1;
  const double pad = 0.08 * (y_max - y_min);
  panel.SetTitle(metric);
  panel.SetLabels("evaluation run", metric);
  panel.SetLimits(1, std::max(2.0, x_max), y_min - pad, y_max + pad);
  panel.DrawAxes();
  std::vector<std::pair<std::string, render::Color>> legend;
  size_t k = 0;
  for (const auto& [method, values] : by_method) {
    const render::Color colour = render::kPalette[k++ % 8];
    std::vector<double> xs;
    for (size_t i = 0; i < values.size(); ++i) xs.push_back(static_cast<double>(i + 1));
    if (values.size() == 1) {
      panel.LinePlot({0.9, 1.1}, {values[0], values[0]}, colour, 3);
    } else {
      panel.LinePlot(xs, values, colour, 2);
    }
    legend.push_back({method, colour});
  }
  panel.Legend(legend);
  return image.EncodePng();
}

// A GIF of the panels, through a temporary file next to the report.
Result<std::string> PreviewGif(const std::vector<render::MotionPanel>& panels, int size,
                               const std::string& scratch) {
  render::RenderOptions options;
  options.panel_width = options.panel_height = size;
  options.fps = 10;
  MP_RETURN_IF_ERROR(render::RenderMotionFile(scratch, panels, options));
  auto bytes = ReadFile(scratch);
  std::error_code ec;
  fs::remove(scratch, ec);
  return bytes;
}

std::optional<Motion> PreviewMotion(const std::string& dir, const std::string& role,
                                    std::string* text) {
  const std::string path = dir + "/preview.npz";
  if (!fs::exists(path)) return std::nullopt;
  auto clips = ReadClips(path);
  if (!clips.ok()) return std::nullopt;
  for (Clip& clip : *clips) {
    if (clip.id != role) continue;
    if (text && !clip.texts.empty()) *text = clip.texts[0];
    return std::move(clip.motion);
  }
  return std::nullopt;
}

constexpr char kStyle[] = R"(<style>
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
h1 { font-size: 1.6em; } h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: 0.4em; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
th { background: #f3f3f3; } td:first-child { text-align: left; }
.paper { color: #666; background: #fafafa; } .sd { color: #777; font-size: 0.85em; }
tr.yardstick td { background: #f7f7fb; }
.holds { color: #0a6b2d; } .fails { color: #a11; } .unknown { color: #666; }
.grid { display: flex; flex-wrap: wrap; gap: 8px; } figure { margin: 0.5em 0; } figcaption { font-size: 0.85em; color: #555; }
code { background: #f3f3f3; padding: 0 3px; }
</style>)";

}  // namespace

std::optional<double> SecondsToReach(const std::vector<double>& r1,
                                     const std::vector<double>& seconds, double bar) {
  if (r1.size() != seconds.size()) return std::nullopt;
  for (size_t k = 0; k < r1.size(); ++k)
    if (r1[k] >= bar) return seconds[k];
  return std::nullopt;
}

std::string Base64(std::string_view bytes) {
  static const char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = (static_cast<uint8_t>(bytes[i]) << 16) |
                       (static_cast<uint8_t>(bytes[i + 1]) << 8) |
                       static_cast<uint8_t>(bytes[i + 2]);
    out += kAlphabet[v >> 18], out += kAlphabet[(v >> 12) & 63], out += kAlphabet[(v >> 6) & 63],
        out += kAlphabet[v & 63];
  }
  if (i + 1 == bytes.size()) {
    const uint32_t v = static_cast<uint8_t>(bytes[i]) << 16;
    out += kAlphabet[v >> 18], out += kAlphabet[(v >> 12) & 63], out += "==";
  } else if (i + 2 == bytes.size()) {
    const uint32_t v =
        (static_cast<uint8_t>(bytes[i]) << 16) | (static_cast<uint8_t>(bytes[i + 1]) << 8);
    out += kAlphabet[v >> 18], out += kAlphabet[(v >> 12) & 63], out += kAlphabet[(v >> 6) & 63],
        out += '=';
  }
  return out;
}

namespace {

// Whether the mean of `model` beats the mean of `untrained` by more than two standard errors (the
// spreads of whichever side has 2+ values; with one value each, by any margin).
bool BeatsUntrained(const Stat& model, const Stat& untrained, bool higher_is_better) {
  const double diff = higher_is_better ? model.mean - untrained.mean : untrained.mean - model.mean;
  const double se = std::sqrt((model.n > 1 ? model.sd * model.sd / model.n : 0) +
                              (untrained.n > 1 ? untrained.sd * untrained.sd / untrained.n : 0));
  return diff > 0 && diff > 2 * se;
}

}  // namespace

ClaimVerdict DecideClaim(const std::vector<double>& better, const std::vector<double>& worse,
                         const std::vector<double>& untrained, bool higher_is_better) {
  return DecideClaim(better, worse, untrained, untrained, higher_is_better);
}

double TwoStandardErrors(const std::vector<double>& better, const std::vector<double>& worse,
                         bool paired) {
  if (paired && better.size() == worse.size() && better.size() > 1) {
    std::vector<double> differences(better.size());
    for (size_t k = 0; k < better.size(); ++k) differences[k] = better[k] - worse[k];
    const Stat d = Summarize(differences);
    return 2 * d.sd / std::sqrt(static_cast<double>(d.n));
  }
  const Stat a = Summarize(better), b = Summarize(worse);
  return 2 * std::sqrt((a.n > 1 ? a.sd * a.sd / a.n : 0) + (b.n > 1 ? b.sd * b.sd / b.n : 0));
}

ClaimVerdict DecideClaim(const std::vector<double>& better, const std::vector<double>& worse,
                         const std::vector<double>& better_untrained,
                         const std::vector<double>& worse_untrained, bool higher_is_better,
                         bool paired) {
  const Stat a = Summarize(better), b = Summarize(worse);
  if (!better_untrained.empty() &&
      !BeatsUntrained(a, Summarize(better_untrained), higher_is_better))
    return ClaimVerdict::kBetterNotTrained;
  if (!worse_untrained.empty() && !BeatsUntrained(b, Summarize(worse_untrained), higher_is_better))
    return ClaimVerdict::kWorseNotTrained;
  if (a.n < 3 || b.n < 3) return ClaimVerdict::kFewSeeds;
  const double diff = higher_is_better ? a.mean - b.mean : b.mean - a.mean;
  const double two_se = TwoStandardErrors(better, worse, paired && a.n == b.n);
  if (diff > two_se) return ClaimVerdict::kHolds;
  if (-diff > two_se) return ClaimVerdict::kDoesNotHold;
  return ClaimVerdict::kWithinErrors;
}

namespace {

// ---- the job's runs
// ---------------------------------------------------------------------------------

// Everything the report reads from a job directory.
struct JobRuns {
  // By evaluation kind (configs/evaluations/*.yaml's `evaluation`), then by `method` string.
  std::map<std::string, std::map<std::string, Method>> evaluations;
  std::vector<TrainCurve> curves;
  std::vector<std::pair<std::string, json>> showcases;  // stage, showcase.json
};

// The evaluation kind of a metrics.json: its "evaluation" key, or for one written before that key,
// the kind whose layout's legacy_key it holds; "" for a stage that is no evaluation.
std::string EvaluationOf(const json& metrics) {
  if (metrics.contains("evaluation") && metrics["evaluation"].is_string())
    return metrics["evaluation"].get<std::string>();
  for (const EvaluationLayout& layout : EvaluationLayouts()) {
    if (!layout.legacy_key.empty() && metrics.contains(layout.legacy_key)) return layout.evaluation;
  }
  return "";
}

// Every stage directory: evaluation metrics, training curves, showcases.
JobRuns ReadJob(const std::string& job) {
  std::vector<std::string> stages;
  for (const auto& entry : fs::directory_iterator(job)) {
    if (entry.is_directory() && entry.path().filename().string()[0] != '.')
      stages.push_back(entry.path().filename().string());
  }
  std::sort(stages.begin(), stages.end());
  JobRuns runs;
  for (const std::string& stage : stages) {
    const std::string task = layout::TaskDir(job + "/" + stage);
    if (auto metrics = ReadJson(layout::MetricsFile(task))) {
      const std::string method = metrics->value("method", stage);
      const std::string evaluation = EvaluationOf(*metrics);
      if (!evaluation.empty()) {
        Method& m = runs.evaluations[evaluation][method];
        m.name = method;
        if (m.row.empty()) m.row = metrics->value("row", std::string());
        if (metrics->value("yardstick", std::string()) == "untrained")
          m.untrained = m.yardstick = true;
        if (metrics->contains("untrained_of") && (*metrics)["untrained_of"].is_array()) {
          for (const json& row : (*metrics)["untrained_of"])
            if (row.is_string()) m.untrained_of.push_back(row.get<std::string>());
        }
        m.runs.push_back({stage, task, *metrics});
      }
    }
    const auto losses = ReadCsvTable(layout::LossesFile(task));
    if (const auto train = losses ? losses->Columns({"step", "loss"}) : std::nullopt) {
      TrainCurve curve;
      curve.stage = stage;
      curve.steps = (*train)[0], curve.losses = (*train)[1];
      if (auto rank = ReadJson(layout::RankSummaryFile(task, 0)))
        curve.seconds = rank->value("seconds", 0.0);
      if (const auto val = ReadCsvTable(layout::ValLossesFile(task))) {
        if (const auto loss = val->Columns({"step", "val_loss"}))
          curve.val_steps = (*loss)[0], curve.val_losses = (*loss)[1];
        // Paired by row: a validation's R@1 and the training seconds when it was taken.
        if (const auto r1 = val->Columns({"val_retrieval_r1", "seconds"}))
          curve.val_r1 = (*r1)[0], curve.val_seconds = (*r1)[1];
      }
      runs.curves.push_back(std::move(curve));
    }
    if (auto showcase = ReadJson(layout::ShowcaseFile(task)))
      runs.showcases.push_back({stage, *showcase});
  }
  for (auto& [evaluation, methods] : runs.evaluations) {
    for (auto& [name, m] : methods) {
      std::sort(m.runs.begin(), m.runs.end(),
                [](const Run& a, const Run& b) { return a.stage < b.stage; });
    }
  }
  return runs;
}

// The methods in the order of `paper`'s rows (others after them), each labelled by its row there
// (none when paper is null).
std::vector<const Method*> ByPaper(std::map<std::string, Method>& methods, const Paper* paper) {
  std::vector<const Method*> out;
  for (auto& [name, m] : methods) {
    m.paper_row.clear();
    m.paper_index = 1000;
    if (const PaperRow* row = paper ? paper->Find(m.row, m.name) : nullptr) {
      m.paper_row = row->row;
      m.paper_index = static_cast<int>(row - paper->rows.data());
    }
    out.push_back(&m);
  }
  std::stable_sort(out.begin(), out.end(), [](const Method* a, const Method* b) {
    return a->paper_index < b->paper_index;
  });
  return out;
}

const Method* ByRow(const std::vector<const Method*>& methods, const std::string& row) {
  for (const Method* m : methods) {
    if (!m->untrained && m->paper_row == row) return m;
  }
  return nullptr;
}

// A table's rows: the yardsticks first (issue 15), the untrained model, then the methods.
std::vector<const Method*> WithYardsticks(const std::vector<Method>& yardsticks,
                                          const std::vector<const Method*>& methods) {
  std::vector<const Method*> rows;
  for (const Method& y : yardsticks) rows.push_back(&y);
  const Method* general = UntrainedRow(methods);
  if (general) rows.push_back(general);
  for (const Method* m : methods) {
    if (m->untrained && m != general) rows.push_back(m);  // the rows' own untrained rows
  }
  for (const Method* m : methods) {
    if (!m->untrained) rows.push_back(m);
  }
  return rows;
}

// The paper's published numbers beside each row.
std::vector<PaperCell> PaperCells(const Paper& paper, const std::vector<const Method*>& rows) {
  std::vector<PaperCell> cells;
  for (const Method* m : rows) {
    PaperCell cell;
    if (const PaperRow* row = m->paper_row.empty() ? nullptr : paper.Find(m->paper_row, ""))
      cell.values.assign(row->values.begin(), row->values.end());
    cells.push_back(cell);
  }
  return cells;
}

std::string Note(const Paper& paper) { return paper.note.empty() ? "" : " " + Escape(paper.note); }

// ---- a paper's tables, in its evaluation kind's layout (configs/evaluations/*.yaml) -----------

// `text` with each {key} replaced by its value.
std::string Fill(std::string text, const std::vector<std::pair<std::string, std::string>>& values) {
  for (const auto& [key, value] : values) {
    const std::string mark = "{" + key + "}";
    for (size_t at = text.find(mark); at != std::string::npos;
         at = text.find(mark, at + value.size()))
      text.replace(at, mark.size(), value);
  }
  return text;
}

const EvaluationLayout* LayoutOf(const std::string& evaluation) {
  for (const EvaluationLayout& layout : EvaluationLayouts()) {
    if (layout.evaluation == evaluation) return &layout;
  }
  return nullptr;
}

// The paper's table (its rows with the yardsticks, its published columns) and, for the first paper
// of its evaluation kind, the kind's other tables.
std::string PaperTables(const Paper& paper, const EvaluationLayout& layout,
                        const std::vector<const Method*>& methods,
                        const std::vector<const Method*>& rows, bool first, int* tables) {
  const bool batches = !layout.protocol_of.empty() && AllBatched(methods, layout.protocol_of);
  const std::string protocol = batches ? "batches" : "all";
  const std::string batch =
      std::to_string(methods.front()->runs.front().metrics.value("batch", int64_t{32}));
  std::string protocol_text;
  for (const auto& [key, text] : layout.protocols) {
    if (key == protocol) protocol_text = Fill(text, {{"batch", batch}});
  }
  const std::vector<std::pair<std::string, std::string>> vars = {{"protocol_text", protocol_text},
                                                                 {"protocol", protocol},
                                                                 {"batch", batch},
                                                                 {"note", Note(paper)}};
  std::vector<Column> columns = layout.columns;
  for (Column& c : columns) c.pointer = Fill(c.pointer, {{"protocol", protocol}});
  std::ostringstream body;
  body << "<h2>" << Escape(paper.title) << "</h2>\n<p>" << Fill(layout.intro, vars) << "</p>\n";
  body << MetricTable(Fill(layout.caption, vars), rows, columns, paper.columns,
                      PaperCells(paper, rows), paper.decimals);
  ++*tables;
  if (!first) return body.str();
  for (const LayoutTable& table : layout.more) {
    if (table.when == "batches" && !batches) continue;
    // A table none of whose columns any row measured (e.g. a metric added after the job ran).
    const bool measured = std::any_of(methods.begin(), methods.end(), [&](const Method* m) {
      return std::any_of(table.columns.begin(), table.columns.end(),
                         [&](const LayoutColumn& c) { return Collect(*m, c.pointer).n > 0; });
    });
    if (!measured) continue;
    body << MetricTable(Fill(table.caption, vars), table.with_yardsticks ? rows : methods,
                        table.columns, {}, {}, 2);
    ++*tables;
  }
  return body.str();
}

// ---- plausibility, claims
// ---------------------------------------------------------------------------

std::string PlausibilitySection(const std::vector<KindMethods>& kinds, int* tables) {
  const bool any = std::any_of(kinds.begin(), kinds.end(), [](const KindMethods& k) {
    return k.layout->plausibility && !k.methods.empty();
  });
  if (!any) return "";
  std::ostringstream body;
  body
      << "<h2>Physical plausibility</h2>\n<p>No pretrained MotionCritic is available offline; "
         "these are the measurable "
      << "proxies, for the generated motions and for their ground truth alike: the fraction of "
         "contact frames whose foot slides faster than 0.15 m/s, the field's skating ratio (GMD's: "
         "frames at 20 fps in which a toe below 5 cm slides faster than 0.5 m/s), "
      << "the mean floor penetration, the fraction of frames floating above the floor, and the "
         "mean jerk.</p>\n<table>\n"
      << "<caption>Plausibility (lower is better; mean over the methods' "
         "seeds)</caption>\n<thead><tr><th>Method</th><th>motions</th>"
      << "<th>foot skate</th><th>skating ratio (GMD)</th><th>penetration "
         "(m)</th><th>floating</th><th>jerk</th></tr></thead>\n<tbody>\n";
  const auto row = [&](const std::string& name, const Method& m, const std::string& side) {
    body << "<tr><td>" << Escape(name) << "</td><td>" << Format(Collect(m, "/motions").mean, 0)
         << "</td>";
    for (const char* k : {"foot_skate_ratio", "skating_ratio_gmd", "penetration_mean_m",
                          "float_ratio", "jerk_mean"}) {
      const Stat s = Collect(m, "/plausibility/" + side + "/" + k);
      body << "<td>" << (s.n ? Format(s.mean, 3) : "&ndash;") << "</td>";
    }
    body << "</tr>\n";
  };
  for (const KindMethods& kind : kinds) {
    const auto& layout = kind.layout->plausibility;
    if (!layout || kind.methods.empty()) continue;
    row(layout->truth_row, *kind.methods.front(), layout->truth_side);
    for (const Method* m : kind.methods) row(RowName(*m), *m, layout->generated_side);
  }
  body << "</tbody></table>\n";
  ++*tables;
  return body.str();
}

// The paper's claims against the methods of its evaluation kind, ordered by it.
std::vector<ClaimCheck> CheckClaims(const Paper& paper, const std::vector<const Method*>& methods) {
  std::string pointer = paper.metric.pointer;
  const size_t at = pointer.find("{protocol}");
  if (at != std::string::npos) {
    // The metric the protocol is read from: the pointer's segments before {protocol}.
    const std::string key = pointer.substr(1, at > 1 ? at - 2 : 0);
    pointer.replace(at, 10, AllBatched(methods, key) ? "batches" : "all");
  }
  std::vector<ClaimCheck> checks;
  for (const PaperClaim& c : paper.claims) {
    checks.push_back(Compare(paper.name, c.claim, ByRow(methods, c.better), ByRow(methods, c.worse),
                             UntrainedFor(methods, c.better), UntrainedFor(methods, c.worse),
                             pointer, paper.metric.name, paper.metric.higher_is_better,
                             paper.metric.decimals));
  }
  return checks;
}

std::string ClaimsSection(const std::vector<ClaimCheck>& claims, int* tables) {
  std::ostringstream body;
  body << "<h2>The papers' claims, checked on this job</h2>\n<p>A claim is <i>not decidable</i> "
          "while a compared model does not "
       << "beat its untrained row (by more than two standard errors), or with fewer than 3 seeds "
          "a side. Otherwise it "
       << "<i>holds</i> when the difference of the means goes the claimed way by more than two "
          "standard errors over the seeds, "
       << "<i>does not hold</i> when it goes the other way by as much, and is <i>not decided</i> "
          "in between.</p>\n"
       << "<table>\n<caption>Claims</caption>\n<thead><tr><th>paper</th><th>claim</"
          "th><th>verdict</th><th>numbers</th></tr></thead>\n<tbody>\n";
  for (const ClaimCheck& c : claims) {
    const std::string cls = c.verdict.rfind("holds", 0) == 0      ? "holds"
                            : c.verdict.rfind("does not", 0) == 0 ? "fails"
                                                                  : "unknown";
    body << "<tr><td>" << Escape(c.paper) << "</td><td>" << Escape(c.claim) << "</td><td class=\""
         << cls << "\">" << Escape(c.verdict) << "</td><td>" << Escape(c.detail) << "</td></tr>\n";
  }
  body << "</tbody></table>\n";
  ++*tables;
  return body.str();
}

// ---- previews, showcases, curves, history
// -----------------------------------------------------------

// Each method's `role` motion from its first run's preview, labelled by its row.
void AppendMethodPanels(const std::vector<const Method*>& methods, const std::string& role,
                        std::vector<render::MotionPanel>* panels) {
  for (const Method* m : methods) {
    if (auto motion = PreviewMotion(m->runs.front().dir, role, nullptr))
      panels->push_back({*motion, RowName(*m), ""});
  }
}

// One GIF per evaluation kind with a preview layout: the first evaluated example's reference
// motions beside each method's; drawn when at least one method's motion is there.
Result<std::string> PreviewSection(const std::vector<KindMethods>& kinds, int panel_size,
                                   const std::string& scratch, int* images) {
  std::ostringstream body;
  bool heading = false;
  for (const KindMethods& kind : kinds) {
    const auto& layout = kind.layout->preview;
    if (!layout || kind.methods.empty()) continue;
    std::vector<render::MotionPanel> panels;
    std::string text;
    const std::string first = kind.methods.front()->runs.front().dir;
    for (const PreviewLayout::Reference& ref : layout->references) {
      std::string ref_text;
      if (auto motion = PreviewMotion(first, ref.role, ref.text ? &ref_text : nullptr))
        panels.push_back({*motion, ref.label, ref_text});
      if (text.empty()) text = ref_text;
    }
    AppendMethodPanels(kind.methods, layout->method_role, &panels);
    if (panels.size() <= layout->references.size()) continue;
    MP_ASSIGN_OR_RETURN(const std::string gif, PreviewGif(panels, panel_size, scratch));
    std::string caption = layout->caption;  // HTML, as the layout's other texts
    if (const size_t at = caption.find("{text}"); at != std::string::npos)
      caption.replace(at, 6, Escape(text));
    if (!heading) body << "<h2>Previews</h2>\n";
    heading = true;
    body << "<figure>" << ImgTag("image/gif", gif, layout->alt, images) << "<figcaption>" << caption
         << "</figcaption></figure>\n";
  }
  return body.str();
}

// A showcase stage's showcase.json: its title, text, images and table (the CMU clips).
std::string ShowcaseSection(const std::string& job, const std::string& stage, const json& showcase,
                            int* tables, int* images) {
  std::ostringstream body;
  body << "<h2>" << Escape(showcase.value("title", stage)) << "</h2>\n";
  if (showcase.contains("text")) body << "<p>" << Escape(showcase.value("text", "")) << "</p>\n";
  const std::string dir = layout::TaskDir(job + "/" + stage);
  for (const json& item : showcase.value("items", json::array())) {
    const std::string file = item.value("image", std::string());
    auto bytes = ReadFile(dir + "/" + file);
    if (file.empty() || !bytes.ok()) continue;
    const std::string mime =
        file.size() > 4 && file.substr(file.size() - 4) == ".png" ? "image/png" : "image/gif";
    body << "<figure>" << ImgTag(mime, *bytes, item.value("caption", file), images)
         << "<figcaption>" << Escape(item.value("caption", file)) << "</figcaption></figure>\n";
  }
  if (showcase.contains("table") && showcase["table"].contains("columns")) {
    const json& table = showcase["table"];
    body << "<table>\n<caption>" << Escape(table.value("caption", stage))
         << "</caption>\n<thead><tr>";
    for (const json& c : table["columns"])
      body << "<th>" << Escape(c.get<std::string>()) << "</th>";
    body << "</tr></thead>\n<tbody>\n";
    for (const json& row : table.value("rows", json::array())) {
      body << "<tr>";
      for (const json& v : row)
        body << "<td>"
             << Escape(v.is_string()         ? v.get<std::string>()
                       : v.is_number_float() ? Format(v.get<double>(), 3)
                                             : v.dump())
             << "</td>";
      body << "</tr>\n";
    }
    body << "</tbody></table>\n";
    ++*tables;
  }
  return body.str();
}

// The held-out R@1 at which the training table gives the time to reach it (issue 15's bar for the
// TMR evaluator on test singles).
constexpr double kRetrievalBar = 40;

// "R@1 (minutes until it first reached kRetrievalBar)" of a curve's last validation, or a dash.
std::string RetrievalCell(const TrainCurve& c) {
  if (c.val_r1.empty()) return "&ndash;";
  const std::optional<double> seconds = SecondsToReach(c.val_r1, c.val_seconds, kRetrievalBar);
  const std::string reached =
      seconds ? Format(*seconds / 60, 1) + " min" : "not " + Format(kRetrievalBar, 0);
  return Format(c.val_r1.back(), 1) + " (" + reached + ")";
}

std::string CurvesSection(const std::vector<TrainCurve>& curves, int* tables, int* images) {
  std::map<std::string, std::vector<const TrainCurve*>> groups;
  for (const TrainCurve& c : curves) groups[BaseStage(c.stage)].push_back(&c);
  std::ostringstream body;
  body << "<h2>Training curves</h2>\n<p>The loss of every train stage (rank 0's losses.csv), "
          "seed replicates overlaid, and the "
       << "loss on fixed batches of the held-out split where the stage validates "
          "(val_losses.csv).</p>\n"
       << "<table>\n<caption>Training</caption>\n<thead><tr><th>stage</th><th>steps</"
          "th><th>first loss</th><th>last loss</th>"
       << "<th>held-out loss: last</th><th>held-out loss: best "
          "(step)</th><th>held-out text&rarr;motion R@1: last (time to "
       << Format(kRetrievalBar, 0) << ")</th><th>seconds</th></tr></thead>\n<tbody>\n";
  for (const TrainCurve& c : curves) {
    std::string last_val = "&ndash;", best_val = "&ndash;";
    if (!c.val_losses.empty()) {
      const size_t best = static_cast<size_t>(
          std::min_element(c.val_losses.begin(), c.val_losses.end()) - c.val_losses.begin());
      last_val = Format(c.val_losses.back(), 4);
      best_val = Format(c.val_losses[best], 4) + " (" + Format(c.val_steps[best] + 1, 0) + ")";
    }
    body << "<tr><td>" << Escape(c.stage) << "</td><td>" << Format(c.steps.back() + 1, 0)
         << "</td><td>" << Format(c.losses.front(), 4) << "</td><td>" << Format(c.losses.back(), 4)
         << "</td><td>" << last_val << "</td><td>" << best_val << "</td><td>" << RetrievalCell(c)
         << "</td><td>" << Format(c.seconds, 1) << "</td></tr>\n";
  }
  body << "</tbody></table>\n<div class=\"grid\">\n";
  ++*tables;
  for (const auto& [name, group] : groups)
    body << ImgTag("image/png", CurvesPng(name, group), "training curve " + name, images) << "\n";
  body << "</div>\n";
  return body.str();
}

Result<std::string> HistorySection(const std::string& path, int* images) {
  MP_ASSIGN_OR_RETURN(const std::vector<MetricRecord> history, ReadHistory(path));
  std::map<std::string, std::map<std::string, std::vector<double>>>
      series;  // metric -> method -> values
  for (const MetricRecord& r : history) series[r.metric][r.method].push_back(r.value);
  std::ostringstream body;
  body << "<h2>Evaluation history</h2>\n<p><code>" << Escape(path) << "</code>: " << history.size()
       << " records; each evaluation run appends its headline metrics with the checkpoint and "
          "the config and data hashes.</p>\n<div class=\"grid\">\n";
  for (const auto& [metric, by_method] : series)
    body << ImgTag("image/png", HistoryPng(metric, by_method), "history " + metric, images) << "\n";
  body << "</div>\n";
  return body.str();
}

std::string Header(const std::string& job, const std::string& title) {
  const std::time_t now = std::time(nullptr);
  char stamp[64];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  std::ostringstream body;
  body << "<h1>motionpipe report: " << Escape(title) << "</h1>\n<p>Job directory <code>"
       << Escape(fs::absolute(job).string()) << "</code>, written " << stamp
       << ". Every number below comes from this job's stages; cells are the mean &plusmn; the "
       << "standard deviation over seed replicates (the <i>seeds</i> column), the best of each "
          "column is bold, and the papers' own "
       << "numbers stand in grey beside them for reference. They were measured on different data "
          "(MotionFix / BABEL with AMASS, "
       << "models trained for days); compare orderings, not values.</p>\n";
  return body.str();
}

}  // namespace

Result<ReportSummary> WriteReport(const ReportOptions& options) {
  const std::string job = options.job_dir;
  if (!fs::is_directory(job)) return NotFound(job + ": not a job directory");
  MP_ASSIGN_OR_RETURN(const std::vector<Paper> papers, LoadPapers(options.papers));
  ReportSummary summary;
  summary.path = options.out_path.empty() ? job + "/report.html" : options.out_path;
  JobRuns runs = ReadJob(job);
  const std::string title =
      options.title.empty() ? fs::path(job).lexically_normal().filename().string() : options.title;
  std::ostringstream body;
  body << Header(job, title);

  // Each paper's table: the yardsticks its evaluations computed, the untrained row, the methods
  // in the paper's order. The first paper of an evaluation kind labels its methods elsewhere.
  const auto methods_of = [&](const Paper* paper, const std::string& evaluation) {
    return ByPaper(runs.evaluations[evaluation], paper);
  };
  const auto first_paper = [&](const std::string& evaluation) -> const Paper* {
    for (const Paper& p : papers) {
      if (p.evaluation == evaluation) return &p;
    }
    return nullptr;
  };
  std::set<std::string> drawn;  // evaluation kinds whose other tables are drawn
  for (const EvaluationLayout& kind : EvaluationLayouts()) {
    const std::string& evaluation = kind.evaluation;
    for (const Paper& paper : papers) {
      if (paper.evaluation != evaluation) continue;
      const std::vector<const Method*> methods = methods_of(&paper, evaluation);
      if (methods.empty()) continue;
      const bool first = drawn.insert(evaluation).second;
      const EvaluationLayout* layout = LayoutOf(evaluation);
      const std::vector<Method> yardsticks = YardstickRows(methods, layout->yardsticks);
      body << PaperTables(paper, *layout, methods, WithYardsticks(yardsticks, methods), first,
                          &summary.tables);
    }
  }
  for (const Paper& paper : papers)
    for (ClaimCheck& c : CheckClaims(paper, methods_of(&paper, paper.evaluation)))
      summary.claims.push_back(std::move(c));
  std::vector<KindMethods> kinds;
  for (const EvaluationLayout& kind : EvaluationLayouts()) {
    kinds.push_back({&kind, methods_of(first_paper(kind.evaluation), kind.evaluation)});
    summary.methods[kind.evaluation] = static_cast<int>(kinds.back().methods.size());
  }

  body << EvaluatorSection(kinds, &summary.tables);
  body << PlausibilitySection(kinds, &summary.tables);
  body << ClaimsSection(summary.claims, &summary.tables);
  if (options.previews) {
    MP_ASSIGN_OR_RETURN(const std::string previews,
                        PreviewSection(kinds, options.panel_size, summary.path + ".preview.tmp.gif",
                                       &summary.images));
    body << previews;
  }
  for (const auto& [stage, showcase] : runs.showcases)
    body << ShowcaseSection(job, stage, showcase, &summary.tables, &summary.images);
  if (!runs.curves.empty()) {
    summary.train_stages = static_cast<int>(runs.curves.size());
    body << CurvesSection(runs.curves, &summary.tables, &summary.images);
  }
  if (!options.history.empty()) {
    MP_ASSIGN_OR_RETURN(const std::string history,
                        HistorySection(options.history, &summary.images));
    body << history;
  }
  const std::string html =
      "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>motionpipe "
      "report: " +
      Escape(title) + "</title>\n" + kStyle + "\n</head>\n<body>\n" + body.str() +
      "</body>\n</html>\n";
  MP_RETURN_IF_ERROR(WriteFileAtomic(summary.path, html));
  return summary;
}

}  // namespace motionpipe::report
