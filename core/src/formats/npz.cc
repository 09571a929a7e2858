#include "motionpipe/formats/npz.h"

#include <algorithm>

#include "motionpipe/base/file.h"
#include "motionpipe/formats/zip.h"

namespace motionpipe {

void Npz::Add(const std::string& name, NpyArray array) {
  for (auto& [existing, value] : arrays_) {
    if (existing == name) {
      value = std::move(array);
      return;
    }
  }
  arrays_.emplace_back(name, std::move(array));
}

const NpyArray* Npz::Find(const std::string& name) const {
  for (const auto& [existing, value] : arrays_) {
    if (existing == name) return &value;
  }
  return nullptr;
}

Result<const NpyArray*> Npz::Get(const std::string& name, const std::string& origin) const {
  if (const NpyArray* found = Find(name)) return found;
  std::string present;
  for (const auto& entry : arrays_) present += (present.empty() ? "" : ", ") + entry.first;
  return NotFound(origin + ": missing array '" + name +
                  "' (present: " + (present.empty() ? "none" : present) + ")");
}

std::optional<NpyArray> Npz::Take(const std::string& name) {
  for (auto& [existing, value] : arrays_) {
    if (existing == name) return std::move(value);
  }
  return std::nullopt;
}

Result<Npz> ParseNpz(std::string_view bytes, const std::string& origin,
                     const std::vector<std::string>& arrays) {
  MemberFilter want;
  if (!arrays.empty()) {
    want = [&arrays](const std::string& member) {
      return std::any_of(arrays.begin(), arrays.end(),
                         [&](const std::string& a) { return member == a + ".npy" || member == a; });
    };
  }
  MP_ASSIGN_OR_RETURN(auto members, ReadZip(bytes, origin, want));
  Npz npz;
  for (auto& member : members) {
    std::string name = member.name;
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".npy") == 0)
      name.resize(name.size() - 4);
    MP_ASSIGN_OR_RETURN(NpyArray array,
                        ParseNpy(std::move(member.data), origin + ": array '" + name + "'"));
    npz.Add(name, std::move(array));
  }
  return npz;
}

std::string SerializeNpz(const Npz& npz, bool compress) {
  ZipWriter writer;
  for (const auto& [name, array] : npz.arrays())
    writer.Add(name + ".npy", SerializeNpy(array), compress);
  return writer.Finish();
}

Result<Npz> ReadNpz(const std::string& path, const std::vector<std::string>& arrays) {
  MP_ASSIGN_OR_RETURN(const MappedFile file, MappedFile::Open(path));
  return ParseNpz(file.data(), path, arrays);
}

Status WriteNpz(const std::string& path, const Npz& npz, bool compress) {
  return WriteFileAtomic(path, SerializeNpz(npz, compress));
}

Result<const NpyArray*> GetShaped(const Npz& npz, const std::string& name,
                                  const std::vector<int64_t>& dims, const std::string& origin) {
  MP_ASSIGN_OR_RETURN(const NpyArray* array, npz.Get(name, origin));
  bool matches = array->shape.size() == dims.size();
  for (size_t d = 0; matches && d < dims.size(); ++d)
    matches = dims[d] < 0 || dims[d] == array->shape[d];
  if (!matches) {
    std::string want = "(";
    for (size_t d = 0; d < dims.size(); ++d)
      want += (d ? ", " : "") + (dims[d] < 0 ? std::string("N") : std::to_string(dims[d]));
    want += dims.size() == 1 ? ",)" : ")";
    return DataLoss(origin + ": array '" + name + "' has shape " + array->ShapeString() +
                    ", expected " + want);
  }
  return array;
}

}  // namespace motionpipe
