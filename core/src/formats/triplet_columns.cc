// Column access to triplets files (see motionfix.h): lenient about content, strict about structure.
// The file is memory-mapped; stored (uncompressed) float32 members are used in place after their
// CRC is checked, deflated ones are inflated in parallel.
#include <algorithm>
#include <cstring>
#include <map>
#include <optional>

#include "motionpipe/base/file.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/formats/zip.h"

namespace motionpipe {

namespace {

// The members of one archive, extracted lazily.
class Archive {
 public:
  static Result<Archive> Open(const std::string& path, const std::vector<std::string>& wanted) {
    Archive archive;
    archive.path_ = path;
    MP_ASSIGN_OR_RETURN(MappedFile file, MappedFile::Open(path));
    archive.file_ = std::make_shared<MappedFile>(std::move(file));
    MP_ASSIGN_OR_RETURN(auto entries, ListZip(archive.file_->data(), path));
    std::vector<ZipEntry> chosen;
    for (auto& entry : entries) {
      std::string name = entry.name;
      if (name.size() > 4 && name.compare(name.size() - 4, 4, ".npy") == 0)
        name.resize(name.size() - 4);
      if (std::find(wanted.begin(), wanted.end(), name) != wanted.end())
        chosen.push_back(std::move(entry));
    }
    // Deflated members are inflated, stored ones checked in place; in parallel, large members
    // first.
    std::sort(chosen.begin(), chosen.end(),
              [](const ZipEntry& a, const ZipEntry& b) { return a.size > b.size; });
    std::vector<std::shared_ptr<std::string>> owned(chosen.size());
    std::vector<Status> errors(chosen.size());
    const auto count = static_cast<int64_t>(chosen.size());
#pragma omp parallel for schedule(dynamic) if (count > 1)
    for (int64_t k = 0; k < count; ++k) {
      const ZipEntry& entry = chosen[static_cast<size_t>(k)];
      if (entry.method == 0) {
        errors[static_cast<size_t>(k)] = CheckZipCrc(entry, entry.payload, path);
      } else if (auto data = ExtractZipEntry(entry, path); data.ok()) {
        owned[static_cast<size_t>(k)] = std::make_shared<std::string>(std::move(*data));
      } else {
        errors[static_cast<size_t>(k)] = data.status();
      }
    }
    for (const Status& error : errors) MP_RETURN_IF_ERROR(error);
    for (size_t k = 0; k < chosen.size(); ++k) {
      std::string name = chosen[k].name;
      if (name.size() > 4 && name.compare(name.size() - 4, 4, ".npy") == 0)
        name.resize(name.size() - 4);
      Member member;
      if (owned[k]) {
        member.bytes = *owned[k];
        member.keep = owned[k];
      } else {
        member.bytes = chosen[k].payload;
        member.keep = archive.file_;
      }
      MP_ASSIGN_OR_RETURN(member.view, ParseNpyView(member.bytes, path + ": array '" + name + "'"));
      archive.members_[name] = std::move(member);
    }
    return archive;
  }

  bool Has(const std::string& name) const { return members_.count(name) > 0; }

  // The array as NpyArray (copied: for the small columns).
  Result<NpyArray> Array(const std::string& name) const {
    const auto it = members_.find(name);
    if (it == members_.end()) return NotFound(path_ + ": no array '" + name + "'");
    return ParseNpy(it->second.bytes, path_ + ": array '" + name + "'");
  }

  // Checks the shape (-1 = any) and returns the view.
  Result<const NpyView*> Shaped(const std::string& name, const std::vector<int64_t>& dims) const {
    const auto it = members_.find(name);
    if (it == members_.end()) return NotFound(path_ + ": no array '" + name + "'");
    const NpyView& v = it->second.view;
    bool matches = v.shape.size() == dims.size();
    for (size_t d = 0; matches && d < dims.size(); ++d)
      matches = dims[d] < 0 || dims[d] == v.shape[d];
    if (!matches) {
      NpyArray shape_of;
      shape_of.shape = v.shape;
      std::string want = "(";
      for (size_t d = 0; d < dims.size(); ++d)
        want += (d ? ", " : "") + (dims[d] < 0 ? std::string("N") : std::to_string(dims[d]));
      want += dims.size() == 1 ? ",)" : ")";
      return DataLoss(path_ + ": array '" + name + "' has shape " + shape_of.ShapeString() +
                      ", expected " + want);
    }
    return &v;
  }

  // Elements from `begin` on as float32: in place when the array is native float32 and aligned,
  // otherwise converted once; `storage` keeps the bytes alive.
  Result<const float*> Floats(const std::string& name, int64_t begin,
                              std::vector<std::shared_ptr<const void>>* storage) const {
    const auto it = members_.find(name);
    if (it == members_.end()) return NotFound(path_ + ": no array '" + name + "'");
    const Member& m = it->second;
    const NpyView& v = m.view;
    if (v.dtype == DType::kFloat32 && v.Native() &&
        reinterpret_cast<uintptr_t>(v.data.data()) % alignof(float) == 0) {
      storage->push_back(m.keep);
      return reinterpret_cast<const float*>(v.data.data()) + begin;
    }
    MP_ASSIGN_OR_RETURN(const NpyArray array, ParseNpy(m.bytes, path_ + ": array '" + name + "'"));
    MP_ASSIGN_OR_RETURN(std::vector<float> converted,
                        array.ToFloat32(path_ + ": array '" + name + "'"));
    auto owned = std::make_shared<const std::vector<float>>(std::move(converted));
    storage->push_back(owned);
    return owned->data() + begin;
  }

  const std::string& path() const { return path_; }

 private:
  struct Member {
    std::string_view bytes;  // the whole .npy
    NpyView view;
    std::shared_ptr<const void> keep;  // the mapping or the inflated buffer
  };
  std::string path_;
  std::shared_ptr<MappedFile> file_;
  std::map<std::string, Member> members_;
};

template <typename T>
std::vector<T> Rows(const std::vector<T>& values, int64_t begin, int64_t end) {
  return std::vector<T>(values.begin() + begin, values.begin() + end);
}

Status LoadSide(const Archive& archive, const std::string& prefix, int64_t n,
                const TripletColumnOptions& options, TripletColumns::Side* side) {
  const std::string& origin = archive.path();
  MP_RETURN_IF_ERROR(archive.Shaped(prefix + "_offsets", {n + 1}).status());
  MP_ASSIGN_OR_RETURN(const NpyArray off, archive.Array(prefix + "_offsets"));
  MP_ASSIGN_OR_RETURN(std::vector<int64_t> offsets,
                      off.ToInt64(origin + ": '" + prefix + "_offsets'"));
  if (offsets.front() != 0) return DataLoss(origin + ": '" + prefix + "_offsets' must start at 0");
  for (size_t k = 1; k < offsets.size(); ++k) {
    if (offsets[k] < offsets[k - 1])
      return DataLoss(origin + ": '" + prefix + "_offsets' decreases at row " +
                      std::to_string(k - 1));
  }
  const int64_t f0 = offsets[static_cast<size_t>(options.row_begin)];
  side->offsets.clear();
  for (int64_t k = options.row_begin; k <= options.row_end; ++k)
    side->offsets.push_back(offsets[static_cast<size_t>(k)] - f0);
  if (!options.motions) return Status::Ok();

  MP_ASSIGN_OR_RETURN(const NpyView* poses, archive.Shaped(prefix + "_poses", {-1, -1, 3}));
  const int64_t frames = poses->shape[0];
  if (offsets.back() != frames) {
    return DataLoss(origin + ": '" + prefix + "_offsets' ends at " +
                    std::to_string(offsets.back()) + " but '" + prefix + "_poses' has " +
                    std::to_string(frames) + " frames");
  }
  side->joints = static_cast<int>(poses->shape[1]);
  MP_ASSIGN_OR_RETURN(side->poses,
                      archive.Floats(prefix + "_poses", f0 * side->joints * 3, &side->storage));
  MP_RETURN_IF_ERROR(archive.Shaped(prefix + "_trans", {frames, 3}).status());
  MP_ASSIGN_OR_RETURN(side->trans, archive.Floats(prefix + "_trans", f0 * 3, &side->storage));
  side->position_joints = 0;
  side->positions = nullptr;
  if (options.positions && archive.Has(prefix + "_joints")) {
    MP_ASSIGN_OR_RETURN(const NpyView* joints, archive.Shaped(prefix + "_joints", {frames, -1, 3}));
    side->position_joints = static_cast<int>(joints->shape[1]);
    MP_ASSIGN_OR_RETURN(
        side->positions,
        archive.Floats(prefix + "_joints", f0 * side->position_joints * 3, &side->storage));
  }
  return Status::Ok();
}

Status CheckFormat(const Archive& archive) {
  MP_RETURN_IF_ERROR(archive.Shaped("format", {}).status());
  MP_ASSIGN_OR_RETURN(const NpyArray format, archive.Array("format"));
  MP_ASSIGN_OR_RETURN(auto text, format.ToStrings(archive.path()));
  if (text.front() != kTripletsFormat) {
    return DataLoss(archive.path() + ": format is '" + text.front() + "', expected '" +
                    kTripletsFormat + "'");
  }
  return Status::Ok();
}

}  // namespace

Result<TripletColumns> ReadTripletColumns(const std::string& path,
                                          const TripletColumnOptions& options_in) {
  std::vector<std::string> wanted = {
      "format",     "ids",      "texts",     "splits",         "fps",
      "edit_start", "edit_end", "edit_kind", "source_offsets", "target_offsets"};
  if (options_in.motions) {
    for (const char* side : {"source", "target"}) {
      wanted.push_back(std::string(side) + "_poses");
      wanted.push_back(std::string(side) + "_trans");
      if (options_in.positions) wanted.push_back(std::string(side) + "_joints");
    }
  }
  MP_ASSIGN_OR_RETURN(const Archive archive, Archive::Open(path, wanted));
  MP_RETURN_IF_ERROR(CheckFormat(archive));
  MP_ASSIGN_OR_RETURN(const NpyView* ids_view, archive.Shaped("ids", {-1}));
  const int64_t n = ids_view->shape[0];
  TripletColumnOptions options = options_in;
  if (options.row_end < 0) options.row_end = n;
  if (options.row_begin < 0 || options.row_begin > options.row_end || options.row_end > n) {
    return InvalidArgument(path + ": rows [" + std::to_string(options.row_begin) + ", " +
                           std::to_string(options.row_end) + ") outside the file's " +
                           std::to_string(n) + " triplets");
  }
  const int64_t b = options.row_begin, e = options.row_end;
  TripletColumns columns;
  columns.origin = path;
  columns.first_row = b;
  columns.rows = e - b;
  auto strings = [&](const std::string& name, std::vector<std::string>* out) -> Status {
    MP_RETURN_IF_ERROR(archive.Shaped(name, {n}).status());
    MP_ASSIGN_OR_RETURN(const NpyArray a, archive.Array(name));
    MP_ASSIGN_OR_RETURN(auto all, a.ToStrings(path + ": '" + name + "'"));
    *out = Rows(all, b, e);
    return Status::Ok();
  };
  auto integers = [&](const std::string& name, std::vector<int32_t>* out) -> Status {
    MP_RETURN_IF_ERROR(archive.Shaped(name, {n}).status());
    MP_ASSIGN_OR_RETURN(const NpyArray a, archive.Array(name));
    MP_ASSIGN_OR_RETURN(auto all, a.ToInt64(path + ": '" + name + "'"));
    out->assign(all.begin() + b, all.begin() + e);
    return Status::Ok();
  };
  MP_RETURN_IF_ERROR(strings("ids", &columns.ids));
  MP_RETURN_IF_ERROR(strings("texts", &columns.texts));
  MP_RETURN_IF_ERROR(strings("splits", &columns.splits));
  MP_RETURN_IF_ERROR(archive.Shaped("fps", {n}).status());
  MP_ASSIGN_OR_RETURN(const NpyArray fps, archive.Array("fps"));
  MP_ASSIGN_OR_RETURN(auto fps_all, fps.ToFloat64(path + ": 'fps'"));
  columns.fps = Rows(fps_all, b, e);
  columns.edit_start.assign(static_cast<size_t>(e - b), -1);
  columns.edit_end.assign(static_cast<size_t>(e - b), -1);
  if (archive.Has("edit_start")) {
    MP_RETURN_IF_ERROR(integers("edit_start", &columns.edit_start));
    MP_RETURN_IF_ERROR(integers("edit_end", &columns.edit_end));
  }
  columns.kinds.assign(static_cast<size_t>(e - b), "");
  if (archive.Has("edit_kind")) MP_RETURN_IF_ERROR(strings("edit_kind", &columns.kinds));
  MP_RETURN_IF_ERROR(LoadSide(archive, "source", n, options, &columns.source));
  MP_RETURN_IF_ERROR(LoadSide(archive, "target", n, options, &columns.target));
  return columns;
}

Result<int64_t> CountTriplets(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const Archive archive, Archive::Open(path, {"format", "ids"}));
  MP_RETURN_IF_ERROR(CheckFormat(archive));
  MP_ASSIGN_OR_RETURN(const NpyView* ids, archive.Shaped("ids", {-1}));
  return ids->shape[0];
}

}  // namespace motionpipe
