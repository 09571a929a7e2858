#include "motionpipe/similarity/filter.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <numeric>
#include <optional>

#include "motionpipe/base/file.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/formats/npz.h"
#include "motionpipe/render/chart.h"

namespace motionpipe::similarity {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// Class boundaries at which predicted "edited" frames (S^N below the boundary) are compared with
// the known edited frames: tau_k = k / K, eq. (10); for regression, 1/3 and 2/3.
std::vector<double> Boundaries(int classes) {
  std::vector<double> out;
  const int k = classes > 0 ? classes : 3;
  for (int b = 1; b < k; ++b) out.push_back(static_cast<double>(b) / k);
  return out;
}

json ConfusionJson(const std::vector<std::array<int64_t, 3>>& counts,
                   const std::vector<double>& boundaries) {
  json out = json::array();
  for (size_t b = 0; b < boundaries.size(); ++b) {
    const auto [tp, fp, fn] = counts[b];
    const double precision =
        tp + fp > 0 ? static_cast<double>(tp) / static_cast<double>(tp + fp) : 0;
    const double recall = tp + fn > 0 ? static_cast<double>(tp) / static_cast<double>(tp + fn) : 0;
    const double f1 = precision + recall > 0 ? 2 * precision * recall / (precision + recall) : 0;
    out.push_back({{"below", boundaries[b]},
                   {"tp", tp},
                   {"fp", fp},
                   {"fn", fn},
                   {"precision", precision},
                   {"recall", recall},
                   {"f1", f1}});
  }
  return out;
}

// Finite SNRs are stored as numbers; infinite ones are counted apart (JSON has no infinity).
struct SnrList {
  std::vector<double> values;
  std::vector<uint8_t> kept;
  int64_t infinite = 0;
};

}  // namespace

Result<std::vector<TripletFile>> ResolveTripletFiles(const std::vector<std::string>& inputs) {
  std::vector<TripletFile> files;
  for (const std::string& input : inputs) {
    std::error_code ec;
    if (fs::is_regular_file(input, ec)) {
      files.push_back({input, 0});
      continue;
    }
    if (!fs::is_directory(input, ec))
      return NotFound(input + ": no such triplets file or directory");
    // The triplet files of a stage's output, else every .npz of a user's folder of converted files.
    std::vector<std::string> found = TripletFilesIn(input);
    for (fs::directory_iterator it(input, ec), end; found.empty() && !ec && it != end;
         it.increment(ec)) {
      if (it->path().extension() == ".npz" && it->is_regular_file(ec))
        found.push_back(it->path().string());
    }
    if (found.empty())
      return NotFound(
          input + ": no triplets files (motionfix/triplets*.npz, triplets*.npz or *.npz) found");
    std::sort(found.begin(), found.end());
    for (auto& path : found) files.push_back({std::move(path), 0});
  }
  for (TripletFile& file : files) {
    MP_ASSIGN_OR_RETURN(file.count, CountTriplets(file.path));
  }
  return files;
}

std::vector<ShardSlice> PlanShard(const std::vector<TripletFile>& files, int shards, int index) {
  std::vector<ShardSlice> slices;
  shards = std::max(1, shards);
  int64_t total = 0;
  for (const auto& file : files) total += file.count;
  if (static_cast<int>(files.size()) >= shards) {
    // Whole files: file f goes to the shard holding the midpoint of its rows.
    int64_t before = 0;
    for (const auto& file : files) {
      const int64_t middle = before + file.count / 2;
      const int owner =
          total > 0 ? static_cast<int>(std::min<int64_t>(shards - 1, middle * shards / total)) : 0;
      if (owner == index && file.count > 0) slices.push_back({file.path, 0, file.count});
      before += file.count;
    }
    // A shard may receive no file (many tiny files with one large one); that is an empty shard.
    return slices;
  }
  const int64_t begin = total * index / shards, end = total * (index + 1) / shards;
  int64_t before = 0;
  for (const auto& file : files) {
    const int64_t lo = std::max(begin, before), hi = std::min(end, before + file.count);
    if (lo < hi) slices.push_back({file.path, lo - before, hi - before});
    before += file.count;
  }
  return slices;
}

namespace {

// What a shard's filter keeps and counts, in slice and row order: the columns of similarity.npz,
// the dropped triplets with their reasons, and the figures of stats.json.
struct ShardOutputs {
  std::vector<std::string> ids, files, splits;
  std::vector<int64_t> rows, offsets{0};
  std::vector<double> snr;
  std::vector<float> similarity, combined, raw_rot, raw_loc;
  std::vector<uint8_t> classes;
  std::vector<int32_t> edit_start, edit_end;
  json dropped = json::array();
  std::map<std::string, int64_t> dropped_by_reason;
  SnrList snr_list;
  std::vector<int64_t> class_frames;
  std::vector<double> boundaries;
  std::vector<std::array<int64_t, 3>> confusion;  // per boundary: tp, fp, fn
  std::map<std::string, std::vector<std::array<int64_t, 3>>> confusion_by_kind;
  std::map<std::string, int64_t> kept_by_split;
  int64_t ground_truth_triplets = 0, triplets = 0, kept_frames = 0;

  explicit ShardOutputs(const SimilarityOptions& options)
      : class_frames(static_cast<size_t>(std::max(options.classes, 1)), 0),
        boundaries(Boundaries(options.classes)),
        confusion(boundaries.size(), {0, 0, 0}) {}

  // Row `k` of `columns` (file `path`) with its similarity result `r`.
  void Add(const TripletColumns& columns, size_t k, const std::string& path,
           const SimilarityResult& r, const SimilarityOptions& options) {
    const int64_t file_row = columns.first_row + static_cast<int64_t>(k);
    if (std::isfinite(r.snr)) {
      snr_list.values.push_back(r.snr);
      snr_list.kept.push_back(r.kept() ? 1 : 0);
    } else if (std::isinf(r.snr)) {
      ++snr_list.infinite;
    }
    if (!r.kept()) {
      json entry = {{"id", columns.ids[k]},
                    {"file", path},
                    {"row", file_row},
                    {"reason", DropReasonName(r.dropped)},
                    {"detail", r.detail}};
      if (std::isfinite(r.snr)) entry["snr"] = r.snr;
      dropped.push_back(std::move(entry));
      ++dropped_by_reason[DropReasonName(r.dropped)];
      return;
    }
    ids.push_back(columns.ids[k]);
    files.push_back(path);
    splits.push_back(columns.splits[k]);
    ++kept_by_split[columns.splits[k]];
    rows.push_back(file_row);
    snr.push_back(r.snr);
    edit_start.push_back(columns.edit_start[k]);
    edit_end.push_back(columns.edit_end[k]);
    const size_t frames = r.normalized.size();
    offsets.push_back(offsets.back() + static_cast<int64_t>(frames));
    kept_frames += static_cast<int64_t>(frames);
    for (size_t i = 0; i < frames; ++i) {
      similarity.push_back(static_cast<float>(r.normalized[i]));
      combined.push_back(static_cast<float>(r.combined[i]));
      raw_rot.push_back(static_cast<float>(r.raw_rot[i]));
      raw_loc.push_back(static_cast<float>(r.raw_loc[i]));
    }
    if (options.classes > 0) {
      classes.insert(classes.end(), r.classes.begin(), r.classes.end());
      for (const uint8_t c : r.classes) ++class_frames[c];
    }
    CountEditRange(columns, k, r);
  }

  // Agreement of the low-similarity frames with the frames the edit is known to change.
  void CountEditRange(const TripletColumns& columns, size_t k, const SimilarityResult& r) {
    const int32_t gs = columns.edit_start[k], ge = columns.edit_end[k];
    if (gs < 0 || ge <= gs) return;
    ++ground_truth_triplets;
    auto& by_kind = confusion_by_kind[columns.kinds[k].empty() ? "unknown" : columns.kinds[k]];
    by_kind.resize(boundaries.size(), {0, 0, 0});
    const size_t frames = r.normalized.size();
    for (size_t b = 0; b < boundaries.size(); ++b) {
      for (size_t i = 0; i < frames; ++i) {
        const bool predicted = r.normalized[i] < boundaries[b];
        const bool edited = static_cast<int64_t>(i) >= gs && static_cast<int64_t>(i) < ge;
        const int slot = predicted && edited ? 0 : (predicted ? 1 : (edited ? 2 : -1));
        if (slot < 0) continue;
        ++confusion[b][static_cast<size_t>(slot)];
        ++by_kind[b][static_cast<size_t>(slot)];
      }
    }
  }

  Status WriteSimilarity(const std::string& path, const SimilarityOptions& options) const {
    const auto n = static_cast<int64_t>(ids.size());
    const auto f = static_cast<int64_t>(similarity.size());
    Npz npz;
    npz.Add("format", NpyArray::ScalarString(kSimilarityFormat));
    npz.Add("options", NpyArray::ScalarString(OptionsToJson(options).dump()));
    npz.Add("ids", NpyArray::Strings({n}, ids));
    npz.Add("files", NpyArray::Strings({n}, files));
    npz.Add("splits", NpyArray::Strings({n}, splits));
    npz.Add("rows", NpyArray::Int64({n}, rows));
    npz.Add("offsets", NpyArray::Int64({n + 1}, offsets));
    npz.Add("snr", NpyArray::Float64({n}, snr));
    npz.Add("similarity", NpyArray::Float32({f}, similarity));
    if (options.classes > 0) npz.Add("classes", NpyArray::UInt8({f}, classes));
    npz.Add("combined", NpyArray::Float32({f}, combined));
    npz.Add("raw_rot", NpyArray::Float32({f}, raw_rot));
    npz.Add("raw_loc", NpyArray::Float32({f}, raw_loc));
    npz.Add("edit_start", NpyArray::Int32({n}, edit_start));
    npz.Add("edit_end", NpyArray::Int32({n}, edit_end));
    return WriteNpz(path, npz, false);
  }

  json Stats(const SimilarityOptions& options, double seconds, int threads) const {
    json by_kind = json::object();
    for (const auto& [kind, counts] : confusion_by_kind)
      by_kind[kind] = ConfusionJson(counts, boundaries);
    return {{"triplets", triplets},
            {"kept", static_cast<int64_t>(ids.size())},
            {"kept_frames", kept_frames},
            {"kept_by_split", kept_by_split},
            {"dropped", dropped_by_reason},
            {"snr", snr_list.values},
            {"snr_kept", snr_list.kept},
            {"snr_infinite", snr_list.infinite},
            {"classes", options.classes},
            {"class_frames", options.classes > 0 ? json(class_frames) : json::array()},
            {"edit_range",
             {{"triplets", ground_truth_triplets},
              {"boundaries", ConfusionJson(confusion, boundaries)},
              {"by_kind", by_kind}}},
            {"options", OptionsToJson(options)},
            {"seconds", seconds},
            {"threads", threads}};
  }
};

}  // namespace

Result<ShardReport> FilterShard(const std::vector<ShardSlice>& slices,
                                const SimilarityOptions& options, int threads,
                                const std::string& out_dir) {
  MP_RETURN_IF_ERROR(ValidateOptions(options, "similarity options"));
  const auto started = std::chrono::steady_clock::now();
  threads = std::max(1, threads);
  ShardOutputs out(options);
  for (const ShardSlice& slice : slices) {
    TripletColumnOptions read;
    read.row_begin = slice.row_begin;
    read.row_end = slice.row_end;
    read.positions = options.locations != LocationSource::kForwardKinematics;
    omp_set_num_threads(threads);
    MP_ASSIGN_OR_RETURN(const TripletColumns columns, ReadTripletColumns(slice.path, read));
    const int64_t n = columns.rows;
    std::vector<SimilarityResult> results(static_cast<size_t>(n));
#pragma omp parallel num_threads(threads)
    {
      Workspace workspace;
#pragma omp for schedule(dynamic, 4)
      for (int64_t row = 0; row < n; ++row) {
        results[static_cast<size_t>(row)] = ComputeSimilarity(
            SideView(columns.source, row), SideView(columns.target, row), options, &workspace);
      }
    }
    out.triplets += n;
    for (size_t k = 0; k < results.size(); ++k)
      out.Add(columns, k, slice.path, results[k], options);
  }
  MP_RETURN_IF_ERROR(MakeDirs(out_dir));
  MP_RETURN_IF_ERROR(out.WriteSimilarity(out_dir + "/similarity.npz", options));
  MP_RETURN_IF_ERROR(WriteFileAtomic(out_dir + "/dropped.json", out.dropped.dump(1) + "\n", false));
  ShardReport report;
  report.triplets = out.triplets;
  report.kept = static_cast<int64_t>(out.ids.size());
  report.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  MP_RETURN_IF_ERROR(WriteFileAtomic(
      out_dir + "/stats.json", out.Stats(options, report.seconds, threads).dump(1) + "\n", false));
  return report;
}

Result<SimilarityTable> ReadSimilarity(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const Npz npz, ReadNpz(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* format, GetShaped(npz, "format", {}, path));
  MP_ASSIGN_OR_RETURN(auto format_text, format->ToStrings(path));
  if (format_text.front() != kSimilarityFormat) {
    return DataLoss(path + ": format is '" + format_text.front() + "', expected '" +
                    kSimilarityFormat + "'");
  }
  SimilarityTable table;
  MP_ASSIGN_OR_RETURN(const NpyArray* options_a, GetShaped(npz, "options", {}, path));
  MP_ASSIGN_OR_RETURN(auto options_text, options_a->ToStrings(path));
  const json options = json::parse(options_text.front(), nullptr, false);
  if (options.is_discarded()) return DataLoss(path + ": 'options' is not JSON");
  MP_ASSIGN_OR_RETURN(table.options, OptionsFromJson(options, path + ": options"));
  MP_ASSIGN_OR_RETURN(const NpyArray* ids, GetShaped(npz, "ids", {-1}, path));
  const int64_t n = ids->shape[0];
  MP_ASSIGN_OR_RETURN(table.ids, ids->ToStrings(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* files, GetShaped(npz, "files", {n}, path));
  MP_ASSIGN_OR_RETURN(table.files, files->ToStrings(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* splits, GetShaped(npz, "splits", {n}, path));
  MP_ASSIGN_OR_RETURN(table.splits, splits->ToStrings(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* rows, GetShaped(npz, "rows", {n}, path));
  MP_ASSIGN_OR_RETURN(table.rows, rows->ToInt64(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* offsets, GetShaped(npz, "offsets", {n + 1}, path));
  MP_ASSIGN_OR_RETURN(table.offsets, offsets->ToInt64(path));
  const int64_t frames = table.offsets.back();
  for (size_t k = 1; k < table.offsets.size(); ++k) {
    if (table.offsets[k] < table.offsets[k - 1] || table.offsets.front() != 0)
      return DataLoss(path + ": 'offsets' are not monotone from 0");
  }
  MP_ASSIGN_OR_RETURN(const NpyArray* snr, GetShaped(npz, "snr", {n}, path));
  MP_ASSIGN_OR_RETURN(table.snr, snr->ToFloat64(path));
  for (const auto& [name, field] :
       std::vector<std::pair<const char*, std::vector<float>*>>{{"similarity", &table.similarity},
                                                                {"combined", &table.combined},
                                                                {"raw_rot", &table.raw_rot},
                                                                {"raw_loc", &table.raw_loc}}) {
    MP_ASSIGN_OR_RETURN(const NpyArray* a, GetShaped(npz, name, {frames}, path));
    MP_ASSIGN_OR_RETURN(*field, a->ToFloat32(path));
  }
  if (npz.Find("classes")) {
    MP_ASSIGN_OR_RETURN(const NpyArray* c, GetShaped(npz, "classes", {frames}, path));
    MP_ASSIGN_OR_RETURN(auto values, c->ToInt64(path));
    table.classes.assign(values.begin(), values.end());
  }
  MP_ASSIGN_OR_RETURN(const NpyArray* es, GetShaped(npz, "edit_start", {n}, path));
  MP_ASSIGN_OR_RETURN(auto starts, es->ToInt64(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* ee, GetShaped(npz, "edit_end", {n}, path));
  MP_ASSIGN_OR_RETURN(auto ends, ee->ToInt64(path));
  table.edit_start.assign(starts.begin(), starts.end());
  table.edit_end.assign(ends.begin(), ends.end());
  return table;
}

namespace {

// Quantile of sorted values (linear interpolation, numpy's default).
double Quantile(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return 0;
  const double at = q * static_cast<double>(sorted.size() - 1);
  const auto lo = static_cast<size_t>(std::floor(at));
  const size_t hi = std::min(lo + 1, sorted.size() - 1);
  return sorted[lo] + (sorted[hi] - sorted[lo]) * (at - static_cast<double>(lo));
}

void AddConfusion(const json& from, std::vector<std::array<int64_t, 3>>* into) {
  into->resize(from.size(), {0, 0, 0});
  for (size_t b = 0; b < from.size(); ++b) {
    (*into)[b][0] += from[b]["tp"].get<int64_t>();
    (*into)[b][1] += from[b]["fp"].get<int64_t>();
    (*into)[b][2] += from[b]["fn"].get<int64_t>();
  }
}

Status DrawSummary(const json& summary, const SimilarityTable* examples, const std::string& path) {
  using namespace render;
  Image image(1600, 1000);
  const double threshold = summary["options"]["snr_threshold"].get<double>();
  {  // MotionSNR histogram, kept and dropped stacked, log x.
    Panel panel(&image, 0, 0, 800, 500);
    panel.SetTitle("MotionSNR (kappa = " + std::to_string(summary["options"]["kappa"].get<int>()) +
                   ")");
    panel.SetLabels("MotionSNR (log scale)", "triplets");
    const auto& hist = summary["snr_histogram"];
    const auto& edges = hist["edges"];
    int64_t peak = 1;
    for (size_t b = 0; b + 1 < edges.size(); ++b) {
      peak = std::max(peak, hist["kept"][b].get<int64_t>() + hist["dropped"][b].get<int64_t>());
    }
    panel.SetLimits(edges.front().get<double>(), edges.back().get<double>(), 0,
                    static_cast<double>(peak) * 1.1, true);
    panel.DrawAxes();
    for (size_t b = 0; b + 1 < edges.size(); ++b) {
      const double lo = edges[b].get<double>(), hi = edges[b + 1].get<double>();
      const double kept = hist["kept"][b].get<double>(), dropped = hist["dropped"][b].get<double>();
      panel.Bar(lo, hi, kept + dropped, kPalette[1], 0.9);
      panel.Bar(lo, hi, kept, kPalette[0], 0.9);
    }
    panel.VerticalLine(threshold, kBlack, 2.0, 8);
    panel.Legend({{"kept", kPalette[0]},
                  {"dropped", kPalette[1]},
                  {"threshold " + TickLabel(threshold), kBlack}});
  }
  {  // Frames per class (or the counts of each drop reason in regression mode).
    Panel panel(&image, 800, 0, 800, 500);
    std::vector<std::string> names;
    std::vector<double> values;
    if (summary["classes"].get<int>() > 0) {
      panel.SetTitle("Frames per similarity class (kept triplets)");
      panel.SetLabels("class (0 = least similar to the source)", "frames");
      for (size_t c = 0; c < summary["class_frames"].size(); ++c) {
        names.push_back(std::to_string(c));
        values.push_back(summary["class_frames"][c].get<double>());
      }
    } else {
      panel.SetTitle("Triplets kept and dropped");
      panel.SetLabels("", "triplets");
      names.push_back("kept");
      values.push_back(summary["kept"].get<double>());
      for (const auto& [reason, count] : summary["dropped"].items()) {
        names.push_back(reason);
        values.push_back(count.get<double>());
      }
    }
    const double peak = values.empty() ? 1 : *std::max_element(values.begin(), values.end());
    panel.SetCategories(names);
    panel.SetLimits(-0.6, static_cast<double>(names.size()) - 0.4, 0, std::max(1.0, peak * 1.15));
    panel.DrawAxes();
    for (size_t c = 0; c < values.size(); ++c) {
      panel.Bar(static_cast<double>(c) - 0.35, static_cast<double>(c) + 0.35, values[c],
                kPalette[(c + 2) % 7]);
    }
    std::vector<std::string> lines = {"kept " + std::to_string(summary["kept"].get<int64_t>()) +
                                      " of " + std::to_string(summary["triplets"].get<int64_t>()) +
                                      " triplets"};
    for (const auto& [reason, count] : summary["dropped"].items())
      lines.push_back(reason + ": " + std::to_string(count.get<int64_t>()));
    panel.Note(lines);
  }
  {  // Example curves with the known edited frames shaded.
    Panel panel(&image, 0, 500, 1100, 500);
    panel.SetTitle("Similarity curves S^N of example triplets (shaded: edited frames)");
    panel.SetLabels("source frame", "S^N");
    int64_t longest = 2;
    std::vector<size_t> picks;
    if (examples != nullptr) {
      const size_t n = examples->ids.size();
      for (size_t k = 0; k < n && picks.size() < 3; k += std::max<size_t>(1, n / 3))
        picks.push_back(k);
      for (const size_t k : picks)
        longest = std::max(longest, examples->offsets[k + 1] - examples->offsets[k]);
    }
    panel.SetLimits(0, static_cast<double>(longest - 1), -0.02, 1.02);
    panel.DrawAxes();
    const int classes = summary["classes"].get<int>();
    for (const double b : Boundaries(classes)) panel.HorizontalLine(b, kGrey, 1.0, 5);
    std::vector<std::pair<std::string, Color>> legend;
    for (size_t e = 0; e < picks.size(); ++e) {
      const size_t k = picks[e];
      const int64_t begin = examples->offsets[k], end = examples->offsets[k + 1];
      std::vector<double> xs, ys;
      for (int64_t i = begin; i < end; ++i) {
        xs.push_back(static_cast<double>(i - begin));
        ys.push_back(examples->similarity[static_cast<size_t>(i)]);
      }
      if (examples->edit_start[k] >= 0)
        panel.ShadeX(examples->edit_start[k], examples->edit_end[k], kPalette[e], 0.12);
      panel.LinePlot(xs, ys, kPalette[e], 2.5);
      char label[64];
      std::snprintf(label, sizeof label, "%s (SNR %.1f)", examples->ids[k].c_str(),
                    examples->snr[k]);
      legend.emplace_back(label, kPalette[e]);
    }
    if (!legend.empty()) panel.Legend(legend);
  }
  {  // Agreement with the known edited frames.
    Panel panel(&image, 1100, 500, 500, 500);
    panel.SetTitle("Low S^N vs. edited frames");
    panel.SetLimits(0, 1, 0, 1);
    std::vector<std::string> lines;
    const auto& er = summary["edit_range"];
    lines.push_back(std::to_string(er["triplets"].get<int64_t>()) + " triplets with");
    lines.push_back("known edited frames");
    lines.push_back("");
    for (const auto& b : er["boundaries"]) {
      char text[96];
      std::snprintf(text, sizeof text, "S^N < %.2f:", b["below"].get<double>());
      lines.push_back(text);
      std::snprintf(text, sizeof text, "  precision %.3f", b["precision"].get<double>());
      lines.push_back(text);
      std::snprintf(text, sizeof text, "  recall    %.3f", b["recall"].get<double>());
      lines.push_back(text);
      std::snprintf(text, sizeof text, "  F1        %.3f", b["f1"].get<double>());
      lines.push_back(text);
    }
    if (er["triplets"].get<int64_t>() == 0)
      lines = {"no triplet has a known", "edited frame range"};
    panel.Note(lines);
  }
  return image.WritePng(path);
}

}  // namespace

Result<json> SummarizeFilter(const std::vector<std::string>& shard_dirs,
                             const std::string& out_dir) {
  MP_RETURN_IF_ERROR(MakeDirs(out_dir));
  json summary = {{"format", "motionpipe.similarity-summary/1"}};
  int64_t triplets = 0, kept = 0, kept_frames = 0, infinite = 0, ground_truth = 0;
  std::map<std::string, int64_t> dropped_by_reason, kept_by_split;
  std::vector<double> snr_all;
  std::vector<uint8_t> snr_kept;
  std::vector<int64_t> class_frames;
  std::vector<std::array<int64_t, 3>> confusion;
  std::map<std::string, std::vector<std::array<int64_t, 3>>> by_kind;
  json options, dropped = json::array(), index = json::array();
  double seconds = 0;
  int classes = 0;
  for (const std::string& dir : shard_dirs) {
    MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(dir + "/stats.json"));
    const json stats = json::parse(text, nullptr, false);
    if (stats.is_discarded()) return DataLoss(dir + "/stats.json: not JSON");
    MP_ASSIGN_OR_RETURN(const std::string dropped_text, ReadFile(dir + "/dropped.json"));
    const json shard_dropped = json::parse(dropped_text, nullptr, false);
    if (!shard_dropped.is_array()) return DataLoss(dir + "/dropped.json: not a JSON list");
    try {
      triplets += stats["triplets"].get<int64_t>();
      kept += stats["kept"].get<int64_t>();
      kept_frames += stats["kept_frames"].get<int64_t>();
      infinite += stats["snr_infinite"].get<int64_t>();
      for (const auto& [reason, count] : stats["dropped"].items())
        dropped_by_reason[reason] += count.get<int64_t>();
      for (const auto& [split, count] : stats["kept_by_split"].items())
        kept_by_split[split] += count.get<int64_t>();
      for (const auto& v : stats["snr"]) snr_all.push_back(v.get<double>());
      for (const auto& v : stats["snr_kept"])
        snr_kept.push_back(static_cast<uint8_t>(v.get<int>()));
      classes = stats["classes"].get<int>();
      const auto& cf = stats["class_frames"];
      class_frames.resize(cf.size(), 0);
      for (size_t c = 0; c < cf.size(); ++c) class_frames[c] += cf[c].get<int64_t>();
      ground_truth += stats["edit_range"]["triplets"].get<int64_t>();
      AddConfusion(stats["edit_range"]["boundaries"], &confusion);
      for (const auto& [kind, counts] : stats["edit_range"]["by_kind"].items())
        AddConfusion(counts, &by_kind[kind]);
      options = stats["options"];
      seconds += stats["seconds"].get<double>();
    } catch (const json::exception& e) {
      return DataLoss(dir + "/stats.json: unexpected content (" + std::string(e.what()) + ")");
    }
    for (const auto& entry : shard_dropped) dropped.push_back(entry);
    std::error_code ec;
    const fs::path relative = fs::relative(fs::path(dir) / "similarity.npz", out_dir, ec);
    index.push_back(
        {{"path", ec ? dir + "/similarity.npz" : relative.string()}, {"kept", stats["kept"]}});
  }
  MP_ASSIGN_OR_RETURN(
      const SimilarityOptions parsed,
      OptionsFromJson(options.is_null() ? json::object() : options, "stats.json options"));
  const std::vector<double> boundaries = Boundaries(parsed.classes);
  confusion.resize(boundaries.size(), {0, 0, 0});

  // SNR histogram on log-spaced bins from 1 (the smallest possible ratio) past the largest value.
  std::vector<double> sorted = snr_all;
  std::sort(sorted.begin(), sorted.end());
  const double top = sorted.empty() ? 10 : std::max(10.0, sorted.back() * 1.05);
  std::vector<double> edges;
  const int bins = 30;
  for (int b = 0; b <= bins; ++b) edges.push_back(std::pow(top, static_cast<double>(b) / bins));
  std::vector<int64_t> hist_kept(bins, 0), hist_dropped(bins, 0);
  for (size_t k = 0; k < snr_all.size(); ++k) {
    const double v = std::max(1.0, snr_all[k]);
    const int b =
        std::clamp(static_cast<int>(std::floor(std::log(v) / std::log(top) * bins)), 0, bins - 1);
    ++(snr_kept[k] ? hist_kept : hist_dropped)[static_cast<size_t>(b)];
  }
  json kinds = json::object();
  for (const auto& [kind, counts] : by_kind) kinds[kind] = ConfusionJson(counts, boundaries);
  json fractions = json::array();
  int64_t class_total = std::accumulate(class_frames.begin(), class_frames.end(), int64_t{0});
  for (const int64_t c : class_frames)
    fractions.push_back(class_total > 0 ? static_cast<double>(c) / static_cast<double>(class_total)
                                        : 0.0);
  summary["triplets"] = triplets;
  summary["kept"] = kept;
  summary["kept_fraction"] =
      triplets > 0 ? static_cast<double>(kept) / static_cast<double>(triplets) : 0.0;
  summary["kept_frames"] = kept_frames;
  summary["kept_by_split"] = kept_by_split;
  summary["dropped"] = dropped_by_reason;
  summary["classes"] = classes;
  summary["class_frames"] = class_frames;
  summary["class_fractions"] = fractions;
  summary["snr"] = {{"count", snr_all.size()},
                    {"infinite", infinite},
                    {"min", sorted.empty() ? 0 : sorted.front()},
                    {"p05", Quantile(sorted, 0.05)},
                    {"p25", Quantile(sorted, 0.25)},
                    {"median", Quantile(sorted, 0.5)},
                    {"p75", Quantile(sorted, 0.75)},
                    {"p95", Quantile(sorted, 0.95)},
                    {"max", sorted.empty() ? 0 : sorted.back()}};
  summary["snr_histogram"] = {{"edges", edges}, {"kept", hist_kept}, {"dropped", hist_dropped}};
  summary["edit_range"] = {{"triplets", ground_truth},
                           {"boundaries", ConfusionJson(confusion, boundaries)},
                           {"by_kind", kinds}};
  summary["options"] = options.is_null() ? OptionsToJson(parsed) : options;
  summary["shards"] = shard_dirs.size();
  summary["task_seconds"] = seconds;

  // Example curves come from the first shard that kept something.
  std::optional<SimilarityTable> examples;
  for (const std::string& dir : shard_dirs) {
    MP_ASSIGN_OR_RETURN(SimilarityTable table, ReadSimilarity(dir + "/similarity.npz"));
    if (!table.ids.empty()) {
      examples = std::move(table);
      break;
    }
  }
  MP_RETURN_IF_ERROR(
      DrawSummary(summary, examples ? &*examples : nullptr, out_dir + "/summary.png"));
  MP_RETURN_IF_ERROR(WriteFileAtomic(out_dir + "/dropped.json", dropped.dump(1) + "\n", false));
  MP_RETURN_IF_ERROR(WriteFileAtomic(
      out_dir + "/index.json",
      json({{"format", kSimilarityFormat}, {"shards", index}}).dump(1) + "\n", false));
  MP_RETURN_IF_ERROR(WriteFileAtomic(out_dir + "/summary.json", summary.dump(1) + "\n", false));
  return summary;
}

std::string FormatFilterSummary(const json& summary) {
  std::string out;
  char line[512];
  const auto triplets = summary["triplets"].get<int64_t>(), kept = summary["kept"].get<int64_t>();
  std::string reasons;
  for (const auto& [reason, count] : summary["dropped"].items()) {
    reasons += (reasons.empty() ? "" : ", ") + reason + " " + std::to_string(count.get<int64_t>());
  }
  std::snprintf(
      line, sizeof line, "filtered %lld triplets: kept %lld (%.1f%%), dropped %lld%s%s%s\n",
      static_cast<long long>(triplets), static_cast<long long>(kept),
      triplets > 0 ? 100.0 * static_cast<double>(kept) / static_cast<double>(triplets) : 0.0,
      static_cast<long long>(triplets - kept), reasons.empty() ? "" : " (", reasons.c_str(),
      reasons.empty() ? "" : ")");
  out += line;
  const auto& snr = summary["snr"];
  std::snprintf(
      line, sizeof line,
      "MotionSNR: p05 %.2f, median %.2f, p95 %.2f, %lld infinite (threshold %.3g, kappa %d)\n",
      snr["p05"].get<double>(), snr["median"].get<double>(), snr["p95"].get<double>(),
      static_cast<long long>(snr["infinite"].get<int64_t>()),
      summary["options"]["snr_threshold"].get<double>(), summary["options"]["kappa"].get<int>());
  out += line;
  if (summary["classes"].get<int>() > 0) {
    out += "frames per class:";
    for (size_t c = 0; c < summary["class_fractions"].size(); ++c) {
      std::snprintf(line, sizeof line, " %zu: %.1f%%", c,
                    100.0 * summary["class_fractions"][c].get<double>());
      out += line;
    }
    out += "\n";
  } else {
    out += "regression targets (no classes)\n";
  }
  const auto& er = summary["edit_range"];
  if (er["triplets"].get<int64_t>() > 0) {
    std::snprintf(line, sizeof line, "known edited frames (%lld triplets):",
                  static_cast<long long>(er["triplets"].get<int64_t>()));
    out += line;
    for (const auto& b : er["boundaries"]) {
      std::snprintf(line, sizeof line, " S^N < %.2f: precision %.3f recall %.3f F1 %.3f;",
                    b["below"].get<double>(), b["precision"].get<double>(),
                    b["recall"].get<double>(), b["f1"].get<double>());
      out += line;
    }
    out.back() = '\n';
  }
  return out;
}

}  // namespace motionpipe::similarity
