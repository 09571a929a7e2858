#include "papers.h"

#include <algorithm>
#include <cctype>
#include <stdexcept>

#include "builtin_evaluations.h"
#include "builtin_papers.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/yaml.h"

namespace motionpipe::report {

namespace {

using Json = nlohmann::ordered_json;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

// A required string field of `j`; `where` names it in the error.
Status GetString(const Json& j, const char* key, const std::string& where, std::string* out) {
  if (!j.contains(key) || !j[key].is_string())
    return InvalidArgument(where + ": '" + key + "' must be a string");
  *out = j[key].get<std::string>();
  return Status::Ok();
}

Status GetStrings(const Json& j, const char* key, const std::string& where,
                  std::vector<std::string>* out) {
  if (!j.contains(key)) return Status::Ok();
  if (!j[key].is_array()) return InvalidArgument(where + ": '" + key + "' must be a list");
  for (const Json& v : j[key]) {
    if (!v.is_string()) return InvalidArgument(where + ": '" + key + "' must list strings");
    out->push_back(v.get<std::string>());
  }
  return Status::Ok();
}

Status ParseRow(const Json& j, const std::string& where, size_t columns, PaperRow* row) {
  if (!j.is_object()) return InvalidArgument(where + ": a row is a map");
  MP_RETURN_IF_ERROR(GetString(j, "row", where, &row->row));
  MP_RETURN_IF_ERROR(GetStrings(j, "methods", where, &row->methods));
  for (std::string& m : row->methods) m = Lower(m);
  if (j.contains("values")) {
    if (!j["values"].is_array() || j["values"].size() != columns)
      return InvalidArgument(where + ": 'values' must list one number per column (" +
                             std::to_string(columns) + ")");
    for (const Json& v : j["values"]) {
      if (!v.is_number()) return InvalidArgument(where + ": 'values' must be numbers");
      row->values.push_back(v.get<double>());
    }
  }
  return Status::Ok();
}

Status GetInt(const Json& j, const char* key, const std::string& where, int* out) {
  if (!j.contains(key)) return Status::Ok();
  if (!j[key].is_number_integer())
    return InvalidArgument(where + ": '" + key + "' must be an integer");
  *out = j[key].get<int>();
  return Status::Ok();
}

Status GetBool(const Json& j, const char* key, const std::string& where, bool* out) {
  if (!j.contains(key)) return Status::Ok();
  if (!j[key].is_boolean()) return InvalidArgument(where + ": '" + key + "' must be true or false");
  *out = j[key].get<bool>();
  return Status::Ok();
}

Status ParseColumns(const Json& j, const std::string& where, int decimals,
                    std::vector<LayoutColumn>* out) {
  if (!j.contains("columns") || !j["columns"].is_array() || j["columns"].empty())
    return InvalidArgument(where + ": 'columns' must be a non-empty list");
  for (size_t c = 0; c < j["columns"].size(); ++c) {
    const Json& col = j["columns"][c];
    const std::string at = where + ": columns[" + std::to_string(c) + "]";
    if (!col.is_object()) return InvalidArgument(at + ": a column is a map");
    LayoutColumn column;
    column.decimals = decimals;
    MP_RETURN_IF_ERROR(GetString(col, "group", at, &column.group));
    MP_RETURN_IF_ERROR(GetString(col, "name", at, &column.name));
    MP_RETURN_IF_ERROR(GetString(col, "pointer", at, &column.pointer));
    if (column.pointer.empty() || column.pointer[0] != '/')
      return InvalidArgument(at + ": 'pointer' must be a JSON pointer (/a/b)");
    MP_RETURN_IF_ERROR(GetInt(col, "decimals", at, &column.decimals));
    MP_RETURN_IF_ERROR(GetBool(col, "higher_is_better", at, &column.higher_is_better));
    MP_RETURN_IF_ERROR(GetBool(col, "bold_best", at, &column.bold_best));
    out->push_back(std::move(column));
  }
  return Status::Ok();
}

Status ParsePlausibility(const Json& j, const std::string& origin, EvaluationLayout* layout) {
  if (!j.contains("plausibility")) return Status::Ok();
  const std::string where = origin + ": plausibility";
  const Json& p = j["plausibility"];
  if (!p.is_object() || !p.contains("truth") || !p["truth"].is_object())
    return InvalidArgument(where + ": a map with 'truth' {side, row} and 'generated'");
  PlausibilityLayout out;
  MP_RETURN_IF_ERROR(GetString(p["truth"], "side", where + ".truth", &out.truth_side));
  MP_RETURN_IF_ERROR(GetString(p["truth"], "row", where + ".truth", &out.truth_row));
  MP_RETURN_IF_ERROR(GetString(p, "generated", where, &out.generated_side));
  layout->plausibility = std::move(out);
  return Status::Ok();
}

Status ParsePreview(const Json& j, const std::string& origin, EvaluationLayout* layout) {
  if (!j.contains("preview")) return Status::Ok();
  const std::string where = origin + ": preview";
  const Json& p = j["preview"];
  if (!p.is_object()) return InvalidArgument(where + ": must be a map");
  PreviewLayout out;
  const Json references = p.value("references", Json::array());
  if (!references.is_array()) return InvalidArgument(where + ": 'references' must be a list");
  for (size_t r = 0; r < references.size(); ++r) {
    const std::string at = where + ".references[" + std::to_string(r) + "]";
    PreviewLayout::Reference ref;
    MP_RETURN_IF_ERROR(GetString(references[r], "role", at, &ref.role));
    MP_RETURN_IF_ERROR(GetString(references[r], "label", at, &ref.label));
    MP_RETURN_IF_ERROR(GetBool(references[r], "text", at, &ref.text));
    out.references.push_back(std::move(ref));
  }
  MP_RETURN_IF_ERROR(GetString(p, "method_role", where, &out.method_role));
  MP_RETURN_IF_ERROR(GetString(p, "alt", where, &out.alt));
  MP_RETURN_IF_ERROR(GetString(p, "caption", where, &out.caption));
  layout->preview = std::move(out);
  return Status::Ok();
}

Status ParseEvaluators(const Json& j, const std::string& origin, EvaluationLayout* layout) {
  const Json rows = j.value("evaluators", Json::array());
  if (!rows.is_array()) return InvalidArgument(origin + ": 'evaluators' must be a list");
  for (size_t r = 0; r < rows.size(); ++r) {
    const std::string at = origin + ": evaluators[" + std::to_string(r) + "]";
    EvaluatorRow row;
    MP_RETURN_IF_ERROR(GetString(rows[r], "label", at, &row.label));
    MP_RETURN_IF_ERROR(GetString(rows[r], "form", at, &row.form));
    MP_RETURN_IF_ERROR(GetStrings(rows[r], "pointers", at, &row.pointers));
    if (rows[r].contains("note")) MP_RETURN_IF_ERROR(GetString(rows[r], "note", at, &row.note));
    const size_t want = row.form == "score_pair" ? 2 : 1;
    if (row.form != "text_motion" && row.form != "motion_motion" && row.form != "score_pair")
      return InvalidArgument(at + ": 'form' must be text_motion, motion_motion or score_pair");
    if (row.pointers.size() != want)
      return InvalidArgument(at + ": 'pointers' must list " + std::to_string(want) +
                             " JSON pointer(s) for form " + row.form);
    for (const std::string& pointer : row.pointers) {
      if (pointer.empty() || pointer[0] != '/')
        return InvalidArgument(at + ": 'pointers' must be JSON pointers (/a/b)");
    }
    layout->evaluators.push_back(std::move(row));
  }
  return Status::Ok();
}

}  // namespace

Result<EvaluationLayout> ParseEvaluationLayout(const std::string& yaml_text,
                                               const std::string& origin) {
  MP_ASSIGN_OR_RETURN(const Json j, ParseYaml(yaml_text, origin));
  if (!j.is_object()) return InvalidArgument(origin + ": an evaluation layout is a YAML map");
  EvaluationLayout layout;
  layout.origin = origin;
  MP_RETURN_IF_ERROR(GetString(j, "evaluation", origin, &layout.evaluation));
  if (j.contains("legacy_key"))
    MP_RETURN_IF_ERROR(GetString(j, "legacy_key", origin, &layout.legacy_key));
  if (j.contains("protocol_of"))
    MP_RETURN_IF_ERROR(GetString(j, "protocol_of", origin, &layout.protocol_of));
  if (j.contains("protocols")) {
    if (!j["protocols"].is_object()) return InvalidArgument(origin + ": 'protocols' must be a map");
    for (const char* key : {"batches", "all"}) {
      std::string text;
      MP_RETURN_IF_ERROR(GetString(j["protocols"], key, origin + ": protocols", &text));
      layout.protocols.push_back({key, text});
    }
  }
  if (!layout.protocol_of.empty() && layout.protocols.empty())
    return InvalidArgument(origin + ": 'protocol_of' needs 'protocols' (batches, all)");
  MP_RETURN_IF_ERROR(GetString(j, "intro", origin, &layout.intro));
  MP_RETURN_IF_ERROR(GetString(j, "caption", origin, &layout.caption));
  MP_RETURN_IF_ERROR(ParseColumns(j, origin, 2, &layout.columns));
  const Json more = j.value("more", Json::array());
  if (!more.is_array()) return InvalidArgument(origin + ": 'more' must be a list");
  for (size_t t = 0; t < more.size(); ++t) {
    const std::string where = origin + ": more[" + std::to_string(t) + "]";
    if (!more[t].is_object()) return InvalidArgument(where + ": a table is a map");
    LayoutTable table;
    MP_RETURN_IF_ERROR(GetString(more[t], "caption", where, &table.caption));
    if (more[t].contains("when"))
      MP_RETURN_IF_ERROR(GetString(more[t], "when", where, &table.when));
    if (!table.when.empty() && table.when != "batches")
      return InvalidArgument(where + ": 'when' must be batches (or absent)");
    MP_RETURN_IF_ERROR(GetBool(more[t], "with_yardsticks", where, &table.with_yardsticks));
    int decimals = 2;
    MP_RETURN_IF_ERROR(GetInt(more[t], "decimals", where, &decimals));
    MP_RETURN_IF_ERROR(ParseColumns(more[t], where, decimals, &table.columns));
    layout.more.push_back(std::move(table));
  }
  const Json yardsticks = j.value("yardsticks", Json::array());
  if (!yardsticks.is_array()) return InvalidArgument(origin + ": 'yardsticks' must be a list");
  for (size_t y = 0; y < yardsticks.size(); ++y) {
    const std::string where = origin + ": yardsticks[" + std::to_string(y) + "]";
    std::string key, row;
    MP_RETURN_IF_ERROR(GetString(yardsticks[y], "key", where, &key));
    MP_RETURN_IF_ERROR(GetString(yardsticks[y], "row", where, &row));
    layout.yardsticks.push_back({key, row});
  }
  MP_RETURN_IF_ERROR(ParsePlausibility(j, origin, &layout));
  MP_RETURN_IF_ERROR(ParsePreview(j, origin, &layout));
  MP_RETURN_IF_ERROR(ParseEvaluators(j, origin, &layout));
  return layout;
}

const std::vector<EvaluationLayout>& EvaluationLayouts() {
  static const std::vector<EvaluationLayout> layouts = [] {
    std::vector<EvaluationLayout> out;
    for (const auto& [name, text] : kBuiltinEvaluations) {
      auto layout = ParseEvaluationLayout(text, std::string("configs/evaluations/") + name);
      // Built in and unit-tested (Papers.TheBuiltInLayoutsParse): a failure is a build defect.
      if (!layout.ok()) throw std::logic_error(layout.status().message());
      out.push_back(std::move(*layout));
    }
    return out;
  }();
  return layouts;
}

const PaperRow* Paper::Find(const std::string& row, const std::string& method) const {
  for (const PaperRow& r : rows) {
    if (!row.empty() && r.row == row) return &r;
  }
  const std::string lower = Lower(method);
  for (const PaperRow& r : rows) {
    if (std::find(r.methods.begin(), r.methods.end(), lower) != r.methods.end()) return &r;
  }
  return nullptr;
}

Result<Paper> ParsePaper(const std::string& yaml_text, const std::string& origin) {
  MP_ASSIGN_OR_RETURN(const Json j, ParseYaml(yaml_text, origin));
  if (!j.is_object()) return InvalidArgument(origin + ": a paper is a YAML map");
  Paper p;
  p.origin = origin;
  MP_RETURN_IF_ERROR(GetString(j, "paper", origin, &p.name));
  MP_RETURN_IF_ERROR(GetString(j, "evaluation", origin, &p.evaluation));
  std::string kinds;  // "edit or generate": the kinds with a layout
  bool known = false;
  for (const EvaluationLayout& layout : EvaluationLayouts()) {
    known = known || layout.evaluation == p.evaluation;
    kinds += (kinds.empty() ? "" : " or ") + layout.evaluation;
  }
  if (!known) return InvalidArgument(origin + ": 'evaluation' must be " + kinds);
  MP_RETURN_IF_ERROR(GetString(j, "title", origin, &p.title));
  if (j.contains("note")) MP_RETURN_IF_ERROR(GetString(j, "note", origin, &p.note));
  MP_RETURN_IF_ERROR(GetStrings(j, "columns", origin, &p.columns));
  if (j.contains("decimals") && !j["decimals"].is_number_integer())
    return InvalidArgument(origin + ": 'decimals' must be an integer");
  p.decimals = j.value("decimals", p.decimals);
  if (!j.contains("rows") || !j["rows"].is_array())
    return InvalidArgument(origin + ": 'rows' must be a list");
  for (size_t r = 0; r < j["rows"].size(); ++r) {
    PaperRow row;
    MP_RETURN_IF_ERROR(ParseRow(j["rows"][r], origin + ": rows[" + std::to_string(r) + "]",
                                p.columns.size(), &row));
    p.rows.push_back(std::move(row));
  }
  if (j.contains("metric")) {
    const Json& m = j["metric"];
    const std::string where = origin + ": metric";
    if (!m.is_object()) return InvalidArgument(where + " must be a map");
    MP_RETURN_IF_ERROR(GetString(m, "name", where, &p.metric.name));
    MP_RETURN_IF_ERROR(GetString(m, "pointer", where, &p.metric.pointer));
    if (p.metric.pointer.empty() || p.metric.pointer[0] != '/')
      return InvalidArgument(where + ": 'pointer' must be a JSON pointer (/a/b)");
    if (m.contains("higher_is_better") && !m["higher_is_better"].is_boolean())
      return InvalidArgument(where + ": 'higher_is_better' must be true or false");
    if (m.contains("decimals") && !m["decimals"].is_number_integer())
      return InvalidArgument(where + ": 'decimals' must be an integer");
    p.metric.higher_is_better = m.value("higher_is_better", true);
    p.metric.decimals = m.value("decimals", p.decimals);
  }
  const Json claims = j.value("claims", Json::array());
  if (!claims.is_array()) return InvalidArgument(origin + ": 'claims' must be a list");
  if (!claims.empty() && p.metric.pointer.empty())
    return InvalidArgument(origin + ": claims need a 'metric'");
  for (size_t c = 0; c < claims.size(); ++c) {
    const std::string where = origin + ": claims[" + std::to_string(c) + "]";
    PaperClaim claim;
    if (!claims[c].is_object()) return InvalidArgument(where + ": a claim is a map");
    MP_RETURN_IF_ERROR(GetString(claims[c], "claim", where, &claim.claim));
    MP_RETURN_IF_ERROR(GetString(claims[c], "better", where, &claim.better));
    MP_RETURN_IF_ERROR(GetString(claims[c], "worse", where, &claim.worse));
    for (const std::string* row : {&claim.better, &claim.worse}) {
      if (!p.Find(*row, ""))
        return InvalidArgument(where + ": '" + *row + "' is not a row of the paper");
    }
    p.claims.push_back(std::move(claim));
  }
  return p;
}

Result<std::vector<Paper>> LoadPapers(const std::vector<std::string>& files) {
  std::vector<Paper> papers;
  const auto add = [&](Paper paper) {
    for (Paper& p : papers) {
      if (p.name == paper.name) {
        p = std::move(paper);
        return;
      }
    }
    papers.push_back(std::move(paper));
  };
  for (const auto& [name, text] : kBuiltinPapers) {
    MP_ASSIGN_OR_RETURN(Paper paper, ParsePaper(text, std::string("configs/papers/") + name));
    add(std::move(paper));
  }
  for (const std::string& file : files) {
    MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(file));
    MP_ASSIGN_OR_RETURN(Paper paper, ParsePaper(text, file));
    add(std::move(paper));
  }
  return papers;
}

}  // namespace motionpipe::report
