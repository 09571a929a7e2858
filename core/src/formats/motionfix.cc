#include "motionpipe/formats/motionfix.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <set>
#include <utility>

#include "motionpipe/base/job_layout.h"

namespace motionpipe {

namespace {

struct SideArrays {
  std::vector<int64_t> offsets{0};
  std::vector<float> poses, trans, joints;
};

void AppendSide(SideArrays* side, const Motion& motion, const std::vector<float>& joints,
                bool with_joints) {
  side->poses.insert(side->poses.end(), motion.poses.begin(), motion.poses.end());
  side->trans.insert(side->trans.end(), motion.trans.begin(), motion.trans.end());
  if (with_joints) side->joints.insert(side->joints.end(), joints.begin(), joints.end());
  side->offsets.push_back(side->offsets.back() + motion.num_frames());
}

void AddSide(Npz* npz, const std::string& prefix, const SideArrays& side, int64_t n,
             bool with_joints) {
  const int64_t frames = side.offsets.back();
  npz->Add(prefix + "_offsets", NpyArray::Int64({n + 1}, side.offsets));
  npz->Add(prefix + "_poses", NpyArray::Float32({frames, kNumJoints, 3}, side.poses));
  npz->Add(prefix + "_trans", NpyArray::Float32({frames, 3}, side.trans));
  if (with_joints)
    npz->Add(prefix + "_joints", NpyArray::Float32({frames, kNumJoints, 3}, side.joints));
}

struct LoadedSide {
  std::vector<int64_t> offsets;
  std::vector<float> poses, trans, joints;
};

Result<LoadedSide> LoadSide(const Npz& npz, const std::string& prefix, int64_t n,
                            const std::string& origin) {
  LoadedSide side;
  MP_ASSIGN_OR_RETURN(const NpyArray* off, GetShaped(npz, prefix + "_offsets", {n + 1}, origin));
  MP_ASSIGN_OR_RETURN(side.offsets, off->ToInt64(origin));
  MP_ASSIGN_OR_RETURN(const NpyArray* poses,
                      GetShaped(npz, prefix + "_poses", {-1, kNumJoints, 3}, origin));
  const int64_t frames = poses->shape[0];
  if (side.offsets.front() != 0 || side.offsets.back() != frames) {
    return DataLoss(origin + ": '" + prefix + "_offsets' must run from 0 to " +
                    std::to_string(frames));
  }
  for (size_t k = 1; k < side.offsets.size(); ++k) {
    if (side.offsets[k] < side.offsets[k - 1])
      return DataLoss(origin + ": '" + prefix + "_offsets' decreases");
  }
  MP_ASSIGN_OR_RETURN(side.poses, poses->ToFloat32(origin));
  MP_ASSIGN_OR_RETURN(const NpyArray* trans,
                      GetShaped(npz, prefix + "_trans", {frames, 3}, origin));
  MP_ASSIGN_OR_RETURN(side.trans, trans->ToFloat32(origin));
  if (npz.Find(prefix + "_joints")) {
    MP_ASSIGN_OR_RETURN(const NpyArray* joints,
                        GetShaped(npz, prefix + "_joints", {frames, kNumJoints, 3}, origin));
    MP_ASSIGN_OR_RETURN(side.joints, joints->ToFloat32(origin));
  }
  return side;
}

void Extract(const LoadedSide& side, size_t index, double fps, Motion* motion,
             std::vector<float>* joints) {
  const int64_t begin = side.offsets[index], end = side.offsets[index + 1];
  motion->fps = fps;
  motion->poses.assign(side.poses.begin() + begin * kNumJoints * 3,
                       side.poses.begin() + end * kNumJoints * 3);
  motion->trans.assign(side.trans.begin() + begin * 3, side.trans.begin() + end * 3);
  if (!side.joints.empty()) {
    joints->assign(side.joints.begin() + begin * kNumJoints * 3,
                   side.joints.begin() + end * kNumJoints * 3);
  }
}

// VisitTripletSides over `files`, several at once (a file to a thread): `prepare(file, motion,
// origin)` sees each side on the thread reading file number `file` (two files may be prepared at
// once, never one file on two threads); `take(file, sides)`, called one file at a time in the
// files' order once a file is read, is told how many of its prepared sides, from its first,
// belong to the visit (all but those past `limit` triplets in all); a file read past the limit or
// after an error is never taken. Returns the triplets taken; the first error in the files' order
// ends it, as a sequential visit's would.
Result<int64_t> VisitTripletFileSides(
    const std::vector<std::string>& files, const std::string& split, int64_t limit,
    const std::function<Status(size_t file, const Motion& motion, const std::string& origin)>&
        prepare,
    const std::function<Status(size_t file, int64_t sides)>& take) {
  int64_t taken = 0;
  Status error = Status::Ok();
  std::atomic<bool> done{false};  // set in order: a file that sees it comes after the last taken
  const int64_t n = static_cast<int64_t>(files.size());
#pragma omp parallel for ordered schedule(dynamic, 1) if (n > 1)
  for (int64_t i = 0; i < n; ++i) {
    const size_t file = static_cast<size_t>(i);
    Result<int64_t> visited = int64_t{0};
    if (!done.load())
      visited = VisitTripletSides(files[file], split, limit,
                                  [&](const Motion& motion, const std::string& origin) {
                                    return prepare(file, motion, origin);
                                  });
#pragma omp ordered
    {
      if (!done.load()) {
        if (!visited.ok()) {
          error = visited.status();
        } else {
          const int64_t count = limit > 0 ? std::min(*visited, limit - taken) : *visited;
          error = take(file, 2 * count);
          taken += count;
        }
        if (!error.ok() || (limit > 0 && taken >= limit)) done.store(true);
      }
    }
  }
  if (!error.ok()) return error;
  return taken;
}

}  // namespace

Npz TripletsToNpz(const std::vector<Triplet>& triplets) {
  const auto n = static_cast<int64_t>(triplets.size());
  const bool with_joints =
      !triplets.empty() && std::all_of(triplets.begin(), triplets.end(), [](const Triplet& t) {
        return !t.source_joints.empty() && !t.target_joints.empty();
      });
  std::vector<std::string> ids, texts, splits, kinds;
  std::vector<double> fps;
  std::vector<int32_t> edit_start, edit_end;
  SideArrays source, target;
  for (const Triplet& t : triplets) {
    ids.push_back(t.id);
    texts.push_back(t.text);
    splits.push_back(t.split);
    fps.push_back(t.source.fps);
    edit_start.push_back(t.edit_start);
    edit_end.push_back(t.edit_end);
    kinds.push_back(t.edit_kind);
    AppendSide(&source, t.source, t.source_joints, with_joints);
    AppendSide(&target, t.target, t.target_joints, with_joints);
  }
  Npz npz;
  npz.Add("format", NpyArray::ScalarString(kTripletsFormat));
  npz.Add("ids", NpyArray::Strings({n}, ids));
  npz.Add("texts", NpyArray::Strings({n}, texts));
  npz.Add("splits", NpyArray::Strings({n}, splits));
  npz.Add("fps", NpyArray::Float64({n}, fps));
  AddSide(&npz, "source", source, n, with_joints);
  AddSide(&npz, "target", target, n, with_joints);
  npz.Add("edit_start", NpyArray::Int32({n}, edit_start));
  npz.Add("edit_end", NpyArray::Int32({n}, edit_end));
  if (std::any_of(kinds.begin(), kinds.end(), [](const std::string& k) { return !k.empty(); })) {
    npz.Add("edit_kind", NpyArray::Strings({n}, kinds));
  }
  return npz;
}

Result<std::vector<Triplet>> TripletsFromNpz(const Npz& npz, const std::string& origin) {
  MP_ASSIGN_OR_RETURN(const NpyArray* format, GetShaped(npz, "format", {}, origin));
  MP_ASSIGN_OR_RETURN(auto format_text, format->ToStrings(origin));
  if (format_text.front() != kTripletsFormat) {
    return DataLoss(origin + ": format is '" + format_text.front() + "', expected '" +
                    kTripletsFormat + "'");
  }
  MP_ASSIGN_OR_RETURN(const NpyArray* ids_a, GetShaped(npz, "ids", {-1}, origin));
  const int64_t n = ids_a->shape[0];
  MP_ASSIGN_OR_RETURN(auto ids, ids_a->ToStrings(origin));
  MP_ASSIGN_OR_RETURN(const NpyArray* texts_a, GetShaped(npz, "texts", {n}, origin));
  MP_ASSIGN_OR_RETURN(auto texts, texts_a->ToStrings(origin));
  MP_ASSIGN_OR_RETURN(const NpyArray* splits_a, GetShaped(npz, "splits", {n}, origin));
  MP_ASSIGN_OR_RETURN(auto splits, splits_a->ToStrings(origin));
  MP_ASSIGN_OR_RETURN(const NpyArray* fps_a, GetShaped(npz, "fps", {n}, origin));
  MP_ASSIGN_OR_RETURN(auto fps, fps_a->ToFloat64(origin));
  MP_ASSIGN_OR_RETURN(LoadedSide source, LoadSide(npz, "source", n, origin));
  MP_ASSIGN_OR_RETURN(LoadedSide target, LoadSide(npz, "target", n, origin));
  std::vector<int64_t> edit_start(static_cast<size_t>(n), -1), edit_end(static_cast<size_t>(n), -1);
  if (npz.Find("edit_start")) {
    MP_ASSIGN_OR_RETURN(const NpyArray* es, GetShaped(npz, "edit_start", {n}, origin));
    MP_ASSIGN_OR_RETURN(edit_start, es->ToInt64(origin));
    MP_ASSIGN_OR_RETURN(const NpyArray* ee, GetShaped(npz, "edit_end", {n}, origin));
    MP_ASSIGN_OR_RETURN(edit_end, ee->ToInt64(origin));
  }
  std::vector<std::string> kinds;
  if (npz.Find("edit_kind")) {
    MP_ASSIGN_OR_RETURN(const NpyArray* ek, GetShaped(npz, "edit_kind", {n}, origin));
    MP_ASSIGN_OR_RETURN(kinds, ek->ToStrings(origin));
  }
  std::vector<Triplet> triplets(static_cast<size_t>(n));
  for (size_t k = 0; k < triplets.size(); ++k) {
    Triplet& t = triplets[k];
    t.id = ids[k];
    t.text = texts[k];
    t.split = splits[k];
    t.edit_start = static_cast<int32_t>(edit_start[k]);
    t.edit_end = static_cast<int32_t>(edit_end[k]);
    if (!kinds.empty()) t.edit_kind = kinds[k];
    Extract(source, k, fps[k], &t.source, &t.source_joints);
    Extract(target, k, fps[k], &t.target, &t.target_joints);
    MP_RETURN_IF_ERROR(ValidateMotion(t.source, origin + ": triplet '" + t.id + "' source"));
    MP_RETURN_IF_ERROR(ValidateMotion(t.target, origin + ": triplet '" + t.id + "' target"));
  }
  return triplets;
}

Status WriteTriplets(const std::string& path, const std::vector<Triplet>& triplets, bool compress) {
  return WriteNpz(path, TripletsToNpz(triplets), compress);
}

Result<std::vector<Triplet>> ReadTriplets(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const Npz npz, ReadNpz(path));
  return TripletsFromNpz(npz, path);
}

std::vector<std::string> TripletFilesIn(const std::string& dir) {
  namespace fs = std::filesystem;
  std::vector<std::string> files;
  for (const std::string& folder : {dir + "/motionfix", dir}) {
    std::error_code ec;
    for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (name.rfind("triplets", 0) == 0 && it->path().extension() == ".npz" &&
          it->is_regular_file(ec))
        files.push_back(it->path().string());
    }
    if (!files.empty()) break;
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::vector<std::string> StageTripletFiles(const std::vector<std::string>& dirs) {
  namespace fs = std::filesystem;
  // A directory's stage directory and whether it is that stage's result ("a/result/" too).
  const auto place = [](const std::string& dir) {
    fs::path path = fs::path(dir).lexically_normal();
    if (!path.has_filename()) path = path.parent_path();
    return std::make_pair(path.parent_path().string(), path.filename() == layout::kResultDirName);
  };
  std::vector<std::vector<std::string>> found;  // each directory's files, listed once
  std::set<std::string> from_result;            // the stages whose result holds triplets
  for (const std::string& dir : dirs) {
    found.push_back(TripletFilesIn(dir));
    const auto [stage, result] = place(dir);
    if (result && !found.back().empty()) from_result.insert(stage);
  }
  std::vector<std::string> files;
  for (size_t k = 0; k < dirs.size(); ++k) {
    const auto [stage, result] = place(dirs[k]);
    if (!result && from_result.count(stage)) continue;  // the result holds this task's triplets
    files.insert(files.end(), found[k].begin(), found[k].end());
  }
  std::sort(files.begin(), files.end());
  files.erase(std::unique(files.begin(), files.end()), files.end());
  return files;
}

Motion SideMotion(const TripletColumns& c, int64_t row, bool source) {
  const auto& side = source ? c.source : c.target;
  const int64_t begin = side.offsets[static_cast<size_t>(row)],
                end = side.offsets[static_cast<size_t>(row) + 1];
  Motion m;
  m.fps = c.fps[static_cast<size_t>(row)];
  m.poses.assign(side.poses + begin * side.joints * 3, side.poses + end * side.joints * 3);
  m.trans.assign(side.trans + begin * 3, side.trans + end * 3);
  return m;
}

Result<int64_t> VisitTripletSides(
    const std::string& path, const std::string& split, int64_t limit,
    const std::function<Status(const Motion& motion, const std::string& origin)>& visit) {
  MP_ASSIGN_OR_RETURN(const TripletColumns c, ReadTripletColumns(path, {0, -1, true, false}));
  int64_t visited = 0;
  for (int64_t r = 0; r < c.rows && (limit <= 0 || visited < limit); ++r) {
    if (c.splits[static_cast<size_t>(r)] != split) continue;
    ++visited;
    for (bool source : {true, false}) {
      const std::string origin = path + ", triplet '" + c.ids[static_cast<size_t>(r)] +
                                 (source ? "' (source)" : "' (target)");
      MP_RETURN_IF_ERROR(visit(SideMotion(c, r, source), origin));
    }
  }
  return visited;
}

Result<int64_t> AddTripletSides(const std::vector<std::string>& files, const std::string& split,
                                int64_t limit, const std::function<Motion(const Motion&)>& convert,
                                LegDatabase* database) {
  std::vector<std::vector<LegDatabase::Rows>> prepared(files.size());
  return VisitTripletFileSides(
      files, split, limit,
      [&](size_t file, const Motion& motion, const std::string& origin) -> Status {
        MP_ASSIGN_OR_RETURN(LegDatabase::Rows rows, database->Prepare(convert(motion), origin));
        prepared[file].push_back(std::move(rows));
        return Status::Ok();
      },
      [&](size_t file, int64_t sides) -> Status {
        std::vector<LegDatabase::Rows> rows = std::move(prepared[file]);
        for (int64_t r = 0; r < sides; ++r)
          MP_RETURN_IF_ERROR(database->Append(std::move(rows[static_cast<size_t>(r)])));
        return Status::Ok();
      });
}

}  // namespace motionpipe
