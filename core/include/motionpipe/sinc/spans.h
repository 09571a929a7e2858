// The action spans SINC trains on (REFERENCE 4.4): from BABEL's frame labels, the sweep over label
// boundaries gives spans with a constant set of actions; spans with one action are Real-Singles,
// spans with two are Real-Pairs. Each span's motion is cut from its AMASS file at 30 fps, and each
// action text gets its body parts from a labeler. Everything is stored in one uncompressed npz
// (`motionpipe.spans/1`) that every synth task maps in place:
//
//   format   ids   splits   sources      <U
//   fps      f8 (N,)
//   offsets  i8 (N+1,)      poses f4 (F, 22, 3)   trans f4 (F, 3)
//   text_a   text_b  <U (N,)    text_b is "" for a single action
//   parts_a  parts_b u1 (N,)   body-part bit masks (bit i = SINC part i) from the labeler
//   labeler  <U ()  the labeler's name
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/babel.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::sinc {

inline constexpr char kSpansFormat[] = "motionpipe.spans/1";

struct SpanTable {
  std::vector<std::string> ids, splits, sources, text_a, text_b;
  std::vector<double> fps;
  std::vector<int64_t> offsets{0};
  std::vector<uint8_t> parts_a, parts_b;
  std::string labeler;
  // Motion data: owned vectors while building; views into the mapped file once read.
  const float* poses = nullptr;  // [F, 22, 3]
  const float* trans = nullptr;  // [F, 3]
  std::vector<float> own_poses, own_trans;
  std::vector<std::shared_ptr<const void>> storage;

  SpanTable() = default;
  SpanTable(SpanTable&&) = default;
  SpanTable& operator=(SpanTable&&) = default;
  SpanTable(const SpanTable&) = delete;  // the motion pointers may point into this object's vectors
  SpanTable& operator=(const SpanTable&) = delete;

  int64_t size() const { return static_cast<int64_t>(ids.size()); }
  int64_t frames(int64_t i) const {
    return offsets[static_cast<size_t>(i) + 1] - offsets[static_cast<size_t>(i)];
  }
  bool single(int64_t i) const { return text_b[static_cast<size_t>(i)].empty(); }
  // A copy of span i's motion.
  Motion MotionOf(int64_t i) const;
  // Appends a span (building a table in memory).
  void Add(const std::string& id, const std::string& split, const std::string& source,
           const Motion& motion, const std::string& a, const std::string& b);
};

struct SpanExtraction {
  double fps = 30;
  BabelSpanOptions sweep;  // 15..600 frames, up to 4 actions (only 1 and 2 are kept)
  bool keep_pairs = true;  // also keep two-action spans (Real-Pairs)
};

// Spans of BABEL files (split = the file's stem: train, val, test) whose `feat_p` are resolved
// under `amass_root`. Sequences whose AMASS file is missing or unreadable are skipped and counted
// in `skipped` (with the first problem in `first_problem`); a BABEL file that cannot be parsed is
// an error.
Result<SpanTable> ExtractBabelSpans(const std::vector<std::string>& babel_files,
                                    const std::string& amass_root, const SpanExtraction& options,
                                    int64_t* skipped = nullptr,
                                    std::string* first_problem = nullptr);

Status WriteSpans(const std::string& path, const SpanTable& table);
// Maps the file; the motion arrays are used in place.
Result<SpanTable> ReadSpans(const std::string& path);

}  // namespace motionpipe::sinc
