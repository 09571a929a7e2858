#include "motionpipe/sinc/spans.h"

#include <algorithm>
#include <cstring>
#include <filesystem>

#include "motionpipe/base/file.h"
#include "motionpipe/formats/amass.h"
#include "motionpipe/formats/npz.h"
#include "motionpipe/formats/zip.h"

namespace motionpipe::sinc {

Motion SpanTable::MotionOf(int64_t i) const {
  Motion m;
  m.fps = fps[static_cast<size_t>(i)];
  const int64_t f0 = offsets[static_cast<size_t>(i)], f1 = offsets[static_cast<size_t>(i) + 1];
  m.poses.assign(poses + f0 * kNumJoints * 3, poses + f1 * kNumJoints * 3);
  m.trans.assign(trans + f0 * 3, trans + f1 * 3);
  return m;
}

void SpanTable::Add(const std::string& id, const std::string& split, const std::string& source,
                    const Motion& motion, const std::string& a, const std::string& b) {
  ids.push_back(id);
  splits.push_back(split);
  sources.push_back(source);
  text_a.push_back(a);
  text_b.push_back(b);
  fps.push_back(motion.fps);
  parts_a.push_back(0);
  parts_b.push_back(0);
  own_poses.insert(own_poses.end(), motion.poses.begin(), motion.poses.end());
  own_trans.insert(own_trans.end(), motion.trans.begin(), motion.trans.end());
  offsets.push_back(offsets.back() + motion.num_frames());
  poses = own_poses.data();
  trans = own_trans.data();
}

Result<SpanTable> ExtractBabelSpans(const std::vector<std::string>& babel_files,
                                    const std::string& amass_root, const SpanExtraction& options,
                                    int64_t* skipped, std::string* first_problem) {
  SpanTable table;
  int64_t missing = 0;
  BabelSpanOptions sweep = options.sweep;
  sweep.fps = options.fps;
  for (const std::string& file : babel_files) {
    MP_ASSIGN_OR_RETURN(const std::vector<BabelSequence> sequences, ReadBabel(file));
    const std::string split = std::filesystem::path(file).stem().string();
    // Read the AMASS files in parallel; spans are added in sequence order.
    std::vector<Result<Clip>> clips(sequences.size(), Status(StatusCode::kNotFound, ""));
#pragma omp parallel for schedule(dynamic)
    for (int64_t k = 0; k < static_cast<int64_t>(sequences.size()); ++k) {
      const auto& seq = sequences[static_cast<size_t>(k)];
      clips[static_cast<size_t>(k)] = ReadAmassNpz(amass_root + "/" + seq.feat_p, options.fps);
    }
    for (size_t k = 0; k < sequences.size(); ++k) {
      const BabelSequence& seq = sequences[k];
      if (!clips[k].ok()) {
        ++missing;
        if (first_problem && first_problem->empty()) *first_problem = clips[k].status().message();
        continue;
      }
      const Motion& motion = clips[k]->motion;
      int n = 0;
      for (const ActionSpan& span : SweepActionSpans(seq, sweep)) {
        if (span.labels.size() > (options.keep_pairs ? 2u : 1u)) continue;
        const int64_t end = std::min<int64_t>(span.end_frame, motion.num_frames());
        if (end - span.start_frame < sweep.min_frames) continue;
        const Motion cut = SliceFrames(motion, span.start_frame, end);
        table.Add(seq.sid + "/" + std::to_string(n++), split,
                  seq.feat_p + ":" + std::to_string(span.start_frame) + "-" + std::to_string(end),
                  cut, span.labels[0], span.labels.size() > 1 ? span.labels[1] : "");
      }
    }
  }
  if (skipped) *skipped = missing;
  return table;
}

Status WriteSpans(const std::string& path, const SpanTable& t) {
  const auto n = static_cast<int64_t>(t.ids.size());
  const int64_t frames = t.offsets.back();
  Npz npz;
  npz.Add("format", NpyArray::ScalarString(kSpansFormat));
  npz.Add("labeler", NpyArray::ScalarString(t.labeler));
  npz.Add("ids", NpyArray::Strings({n}, t.ids));
  npz.Add("splits", NpyArray::Strings({n}, t.splits));
  npz.Add("sources", NpyArray::Strings({n}, t.sources));
  npz.Add("text_a", NpyArray::Strings({n}, t.text_a));
  npz.Add("text_b", NpyArray::Strings({n}, t.text_b));
  npz.Add("fps", NpyArray::Float64({n}, t.fps));
  npz.Add("offsets", NpyArray::Int64({n + 1}, t.offsets));
  npz.Add("parts_a", NpyArray::UInt8({n}, t.parts_a));
  npz.Add("parts_b", NpyArray::UInt8({n}, t.parts_b));
  npz.Add("poses",
          NpyArray::Float32({frames, kNumJoints, 3},
                            std::vector<float>(t.poses, t.poses + frames * kNumJoints * 3)));
  npz.Add("trans",
          NpyArray::Float32({frames, 3}, std::vector<float>(t.trans, t.trans + frames * 3)));
  return WriteNpz(path, npz, false);
}

Result<SpanTable> ReadSpans(const std::string& path) {
  MP_ASSIGN_OR_RETURN(MappedFile mapped, MappedFile::Open(path));
  auto file = std::make_shared<MappedFile>(std::move(mapped));
  MP_ASSIGN_OR_RETURN(const std::vector<ZipEntry> entries, ListZip(file->data(), path));
  SpanTable t;
  Npz small;  // everything but the motion arrays, parsed normally
  const NpyView* poses = nullptr;
  const NpyView* trans = nullptr;
  std::vector<NpyView> views;
  views.reserve(entries.size());
  for (const ZipEntry& entry : entries) {
    std::string name = entry.name;
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".npy") == 0)
      name.resize(name.size() - 4);
    if ((name == "poses" || name == "trans") && entry.method == 0) {
      MP_RETURN_IF_ERROR(CheckZipCrc(entry, entry.payload, path));
      MP_ASSIGN_OR_RETURN(NpyView view,
                          ParseNpyView(entry.payload, path + ": array '" + name + "'"));
      if (view.dtype != DType::kFloat32 || !view.Native() ||
          reinterpret_cast<uintptr_t>(view.data.data()) % 4 != 0) {
        return DataLoss(path + ": array '" + name +
                        "' must be native float32 (write the file with motionpipe)");
      }
      views.push_back(view);
      (name == "poses" ? poses : trans) = &views.back();
      continue;
    }
    MP_ASSIGN_OR_RETURN(std::string data, ExtractZipEntry(entry, path));
    MP_ASSIGN_OR_RETURN(NpyArray array, ParseNpy(std::move(data), path + ": array '" + name + "'"));
    small.Add(name, std::move(array));
  }
  MP_ASSIGN_OR_RETURN(const NpyArray* format, GetShaped(small, "format", {}, path));
  MP_ASSIGN_OR_RETURN(auto format_text, format->ToStrings(path));
  if (format_text.front() != kSpansFormat)
    return DataLoss(path + ": format is '" + format_text.front() + "', expected '" + kSpansFormat +
                    "'");
  MP_ASSIGN_OR_RETURN(const NpyArray* ids, GetShaped(small, "ids", {-1}, path));
  const int64_t n = ids->shape[0];
  MP_ASSIGN_OR_RETURN(t.ids, ids->ToStrings(path));
  for (const auto& [name, field] :
       std::vector<std::pair<const char*, std::vector<std::string>*>>{{"splits", &t.splits},
                                                                      {"sources", &t.sources},
                                                                      {"text_a", &t.text_a},
                                                                      {"text_b", &t.text_b}}) {
    MP_ASSIGN_OR_RETURN(const NpyArray* a, GetShaped(small, name, {n}, path));
    MP_ASSIGN_OR_RETURN(*field, a->ToStrings(path + ": '" + name + "'"));
  }
  MP_ASSIGN_OR_RETURN(const NpyArray* labeler, GetShaped(small, "labeler", {}, path));
  MP_ASSIGN_OR_RETURN(auto labeler_text, labeler->ToStrings(path));
  t.labeler = labeler_text.front();
  MP_ASSIGN_OR_RETURN(const NpyArray* fps, GetShaped(small, "fps", {n}, path));
  MP_ASSIGN_OR_RETURN(t.fps, fps->ToFloat64(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* offsets, GetShaped(small, "offsets", {n + 1}, path));
  MP_ASSIGN_OR_RETURN(t.offsets, offsets->ToInt64(path));
  for (const auto& [name, field] : std::vector<std::pair<const char*, std::vector<uint8_t>*>>{
           {"parts_a", &t.parts_a}, {"parts_b", &t.parts_b}}) {
    MP_ASSIGN_OR_RETURN(const NpyArray* a, GetShaped(small, name, {n}, path));
    MP_ASSIGN_OR_RETURN(auto values, a->ToInt64(path));
    field->assign(values.begin(), values.end());
  }
  if (!poses || !trans) return DataLoss(path + ": needs stored 'poses' and 'trans' arrays");
  const int64_t frames = t.offsets.back();
  if (t.offsets.front() != 0 || poses->shape != std::vector<int64_t>{frames, kNumJoints, 3} ||
      trans->shape != std::vector<int64_t>{frames, 3}) {
    return DataLoss(path + ": offsets and motion arrays disagree");
  }
  for (size_t k = 1; k < t.offsets.size(); ++k) {
    if (t.offsets[k] < t.offsets[k - 1]) return DataLoss(path + ": 'offsets' decreases");
  }
  t.poses = reinterpret_cast<const float*>(poses->data.data());
  t.trans = reinterpret_cast<const float*>(trans->data.data());
  t.storage.push_back(file);
  return t;
}

}  // namespace motionpipe::sinc
