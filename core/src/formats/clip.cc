#include "motionpipe/formats/clip.h"

#include <algorithm>
#include <cctype>
#include <cmath>

#include "motionpipe/formats/amass.h"
#include "motionpipe/formats/bvh.h"

namespace motionpipe {

Status ValidateClip(const Clip& clip, const std::string& origin) {
  const std::string where = origin + (clip.id.empty() ? "" : " clip '" + clip.id + "'");
  MP_RETURN_IF_ERROR(ValidateMotion(clip.motion, where));
  const int64_t frames = clip.motion.num_frames();
  if (!clip.joints.empty()) {
    if (clip.joints.size() != static_cast<size_t>(frames) * kNumJoints * 3) {
      return DataLoss(where + ": joints are not [T, 22, 3]");
    }
    for (float v : clip.joints) {
      if (!std::isfinite(v)) return DataLoss(where + ": non-finite joint position");
    }
  }
  for (const Segment& seg : clip.segments) {
    if (seg.start_frame < 0 || seg.end_frame <= seg.start_frame || seg.end_frame > frames) {
      return DataLoss(where + ": segment '" + seg.text + "' [" + std::to_string(seg.start_frame) +
                      ", " + std::to_string(seg.end_frame) + ") lies outside the clip's " +
                      std::to_string(frames) + " frames");
    }
  }
  return Status::Ok();
}

Npz ClipsToNpz(const std::vector<Clip>& clips) {
  std::vector<std::string> ids, sources, texts, seg_text, seg_action;
  std::vector<double> fps;
  std::vector<int64_t> offsets{0}, text_offsets{0}, seg_offsets{0};
  std::vector<float> poses, trans, joints;
  std::vector<int32_t> seg_start, seg_end;
  std::vector<uint8_t> seg_parts;
  const bool all_joints =
      !clips.empty() &&
      std::all_of(clips.begin(), clips.end(), [](const Clip& c) { return !c.joints.empty(); });
  for (const Clip& clip : clips) {
    ids.push_back(clip.id);
    sources.push_back(clip.source);
    fps.push_back(clip.motion.fps);
    poses.insert(poses.end(), clip.motion.poses.begin(), clip.motion.poses.end());
    trans.insert(trans.end(), clip.motion.trans.begin(), clip.motion.trans.end());
    if (all_joints) joints.insert(joints.end(), clip.joints.begin(), clip.joints.end());
    offsets.push_back(offsets.back() + clip.motion.num_frames());
    texts.insert(texts.end(), clip.texts.begin(), clip.texts.end());
    text_offsets.push_back(static_cast<int64_t>(texts.size()));
    for (const Segment& seg : clip.segments) {
      seg_start.push_back(seg.start_frame);
      seg_end.push_back(seg.end_frame);
      seg_text.push_back(seg.text);
      seg_action.push_back(seg.action);
      for (int part = 0; part < kNumBodyParts; ++part) seg_parts.push_back((seg.parts >> part) & 1);
    }
    seg_offsets.push_back(static_cast<int64_t>(seg_start.size()));
  }
  const auto n = static_cast<int64_t>(clips.size());
  const int64_t frames = offsets.back();
  Npz npz;
  npz.Add("format", NpyArray::ScalarString(kClipsFormat));
  npz.Add("ids", NpyArray::Strings({n}, ids));
  npz.Add("sources", NpyArray::Strings({n}, sources));
  npz.Add("fps", NpyArray::Float64({n}, fps));
  npz.Add("offsets", NpyArray::Int64({n + 1}, offsets));
  npz.Add("poses", NpyArray::Float32({frames, kNumJoints, 3}, poses));
  npz.Add("trans", NpyArray::Float32({frames, 3}, trans));
  if (all_joints) npz.Add("joints", NpyArray::Float32({frames, kNumJoints, 3}, joints));
  npz.Add("text_offsets", NpyArray::Int64({n + 1}, text_offsets));
  npz.Add("texts", NpyArray::Strings({static_cast<int64_t>(texts.size())}, texts));
  const auto segs = static_cast<int64_t>(seg_start.size());
  npz.Add("seg_offsets", NpyArray::Int64({n + 1}, seg_offsets));
  npz.Add("seg_start", NpyArray::Int32({segs}, seg_start));
  npz.Add("seg_end", NpyArray::Int32({segs}, seg_end));
  npz.Add("seg_text", NpyArray::Strings({segs}, seg_text));
  npz.Add("seg_parts", NpyArray::Bool({segs, kNumBodyParts}, seg_parts));
  if (std::any_of(seg_action.begin(), seg_action.end(),
                  [](const std::string& a) { return !a.empty(); })) {
    npz.Add("seg_action", NpyArray::Strings({segs}, seg_action));
  }
  return npz;
}

namespace {
// Checks that `offsets` has n+1 entries, starts at 0, never decreases and ends at `total`.
Status CheckOffsets(const std::vector<int64_t>& offsets, int64_t n, int64_t total,
                    const std::string& name, const std::string& origin) {
  if (static_cast<int64_t>(offsets.size()) != n + 1 || offsets.front() != 0 ||
      offsets.back() != total) {
    return DataLoss(origin + ": '" + name + "' must have N+1 entries from 0 to " +
                    std::to_string(total));
  }
  for (size_t k = 1; k < offsets.size(); ++k) {
    if (offsets[k] < offsets[k - 1])
      return DataLoss(origin + ": '" + name + "' decreases at entry " + std::to_string(k));
  }
  return Status::Ok();
}
}  // namespace

Result<std::vector<Clip>> ClipsFromNpz(const Npz& npz, const std::string& origin) {
  MP_ASSIGN_OR_RETURN(const NpyArray* format, GetShaped(npz, "format", {}, origin));
  MP_ASSIGN_OR_RETURN(auto format_text, format->ToStrings(origin + ": array 'format'"));
  if (format_text.front() != kClipsFormat) {
    return DataLoss(origin + ": format is '" + format_text.front() + "', expected '" +
                    kClipsFormat + "'");
  }
  MP_ASSIGN_OR_RETURN(const NpyArray* ids_a, GetShaped(npz, "ids", {-1}, origin));
  const int64_t n = ids_a->shape[0];
  MP_ASSIGN_OR_RETURN(auto ids, ids_a->ToStrings(origin + ": 'ids'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* sources_a, GetShaped(npz, "sources", {n}, origin));
  MP_ASSIGN_OR_RETURN(auto sources, sources_a->ToStrings(origin + ": 'sources'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* fps_a, GetShaped(npz, "fps", {n}, origin));
  MP_ASSIGN_OR_RETURN(auto fps, fps_a->ToFloat64(origin + ": 'fps'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* off_a, GetShaped(npz, "offsets", {n + 1}, origin));
  MP_ASSIGN_OR_RETURN(auto offsets, off_a->ToInt64(origin + ": 'offsets'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* poses_a,
                      GetShaped(npz, "poses", {-1, kNumJoints, 3}, origin));
  const int64_t frames = poses_a->shape[0];
  MP_RETURN_IF_ERROR(CheckOffsets(offsets, n, frames, "offsets", origin));
  MP_ASSIGN_OR_RETURN(auto poses, poses_a->ToFloat32(origin + ": 'poses'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* trans_a, GetShaped(npz, "trans", {frames, 3}, origin));
  MP_ASSIGN_OR_RETURN(auto trans, trans_a->ToFloat32(origin + ": 'trans'"));
  std::vector<float> joints;
  if (npz.Find("joints")) {
    MP_ASSIGN_OR_RETURN(const NpyArray* joints_a,
                        GetShaped(npz, "joints", {frames, kNumJoints, 3}, origin));
    MP_ASSIGN_OR_RETURN(joints, joints_a->ToFloat32(origin + ": 'joints'"));
  }
  MP_ASSIGN_OR_RETURN(const NpyArray* texts_a, GetShaped(npz, "texts", {-1}, origin));
  MP_ASSIGN_OR_RETURN(auto texts, texts_a->ToStrings(origin + ": 'texts'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* toff_a, GetShaped(npz, "text_offsets", {n + 1}, origin));
  MP_ASSIGN_OR_RETURN(auto text_offsets, toff_a->ToInt64(origin + ": 'text_offsets'"));
  MP_RETURN_IF_ERROR(
      CheckOffsets(text_offsets, n, static_cast<int64_t>(texts.size()), "text_offsets", origin));
  MP_ASSIGN_OR_RETURN(const NpyArray* soff_a, GetShaped(npz, "seg_offsets", {n + 1}, origin));
  MP_ASSIGN_OR_RETURN(auto seg_offsets, soff_a->ToInt64(origin + ": 'seg_offsets'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* sstart_a, GetShaped(npz, "seg_start", {-1}, origin));
  const int64_t segs = sstart_a->shape[0];
  MP_RETURN_IF_ERROR(CheckOffsets(seg_offsets, n, segs, "seg_offsets", origin));
  MP_ASSIGN_OR_RETURN(auto seg_start, sstart_a->ToInt64(origin + ": 'seg_start'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* send_a, GetShaped(npz, "seg_end", {segs}, origin));
  MP_ASSIGN_OR_RETURN(auto seg_end, send_a->ToInt64(origin + ": 'seg_end'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* stext_a, GetShaped(npz, "seg_text", {segs}, origin));
  MP_ASSIGN_OR_RETURN(auto seg_text, stext_a->ToStrings(origin + ": 'seg_text'"));
  MP_ASSIGN_OR_RETURN(const NpyArray* sparts_a,
                      GetShaped(npz, "seg_parts", {segs, kNumBodyParts}, origin));
  MP_ASSIGN_OR_RETURN(auto seg_parts, sparts_a->ToInt64(origin + ": 'seg_parts'"));
  std::vector<std::string> seg_action;
  if (npz.Find("seg_action")) {
    MP_ASSIGN_OR_RETURN(const NpyArray* saction_a, GetShaped(npz, "seg_action", {segs}, origin));
    MP_ASSIGN_OR_RETURN(seg_action, saction_a->ToStrings(origin + ": 'seg_action'"));
  }

  std::vector<Clip> clips(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) {
    Clip& clip = clips[static_cast<size_t>(i)];
    const auto idx = static_cast<size_t>(i);
    clip.id = ids[idx];
    clip.source = sources[idx];
    clip.motion.fps = fps[idx];
    const int64_t begin = offsets[idx], end = offsets[idx + 1];
    clip.motion.poses.assign(poses.begin() + begin * kNumJoints * 3,
                             poses.begin() + end * kNumJoints * 3);
    clip.motion.trans.assign(trans.begin() + begin * 3, trans.begin() + end * 3);
    if (!joints.empty())
      clip.joints.assign(joints.begin() + begin * kNumJoints * 3,
                         joints.begin() + end * kNumJoints * 3);
    clip.texts.assign(texts.begin() + text_offsets[idx], texts.begin() + text_offsets[idx + 1]);
    for (int64_t s = seg_offsets[idx]; s < seg_offsets[idx + 1]; ++s) {
      const auto sidx = static_cast<size_t>(s);
      Segment seg;
      seg.start_frame = static_cast<int32_t>(seg_start[sidx]);
      seg.end_frame = static_cast<int32_t>(seg_end[sidx]);
      seg.text = seg_text[sidx];
      if (!seg_action.empty()) seg.action = seg_action[sidx];
      for (int part = 0; part < kNumBodyParts; ++part) {
        if (seg_parts[sidx * kNumBodyParts + static_cast<size_t>(part)])
          seg.parts |= static_cast<PartSet>(1u << part);
      }
      clip.segments.push_back(std::move(seg));
    }
    MP_RETURN_IF_ERROR(ValidateClip(clip, origin));
  }
  return clips;
}

Status WriteClips(const std::string& path, const std::vector<Clip>& clips, bool compress) {
  for (const Clip& clip : clips) MP_RETURN_IF_ERROR(ValidateClip(clip, path));
  return WriteNpz(path, ClipsToNpz(clips), compress);
}

Result<std::vector<Clip>> ReadClips(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const Npz npz, ReadNpz(path));
  return ClipsFromNpz(npz, path);
}

Result<std::vector<Clip>> LoadMotionFile(const std::string& path, double fps) {
  std::vector<Clip> clips;
  const auto ends_with = [&](const std::string& suffix) {
    return path.size() >= suffix.size() &&
           std::equal(suffix.rbegin(), suffix.rend(), path.rbegin(),
                      [](char a, char b) { return std::tolower(a) == std::tolower(b); });
  };
  if (ends_with(".bvh")) {
    MP_ASSIGN_OR_RETURN(Clip clip, ImportBvhFile(path, BvhImportOptions{}));
    clips.push_back(std::move(clip));
  } else {
    MP_ASSIGN_OR_RETURN(const Npz npz, ReadNpz(path));
    if (npz.Find("format")) {
      MP_ASSIGN_OR_RETURN(clips, ClipsFromNpz(npz, path));
    } else if (npz.Find("poses") && npz.Find("trans")) {
      MP_ASSIGN_OR_RETURN(Clip clip, AmassClipFromNpz(npz, path));
      clips.push_back(std::move(clip));
    } else {
      return DataLoss(
          path +
          ": neither a motionpipe clip file (no 'format') nor an AMASS npz (no 'poses'/'trans')");
    }
  }
  if (fps > 0) {
    for (Clip& clip : clips) {
      if (std::abs(clip.motion.fps - fps) < 1e-9) continue;
      // Output frame f shows source frame floor(f * step): source range [s, e) becomes
      // [ceil(s/step), ceil(e/step)).
      const double step = clip.motion.fps / fps;
      MP_RETURN_IF_ERROR(CheckResample(clip.motion, fps, path + ": clip " + clip.id));
      clip.motion = Resample(clip.motion, fps);
      clip.joints.clear();
      const auto frames = static_cast<int32_t>(clip.motion.num_frames());
      std::vector<Segment> kept;
      for (Segment seg : clip.segments) {
        seg.start_frame =
            std::min(frames, static_cast<int32_t>(std::ceil(seg.start_frame / step - 1e-9)));
        seg.end_frame =
            std::min(frames, static_cast<int32_t>(std::ceil(seg.end_frame / step - 1e-9)));
        if (seg.end_frame > seg.start_frame) kept.push_back(std::move(seg));
      }
      clip.segments = std::move(kept);
    }
  }
  return clips;
}

}  // namespace motionpipe
