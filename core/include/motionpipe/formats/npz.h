// numpy .npz archives: named .npy members inside a ZIP file. Readable by numpy.load and written
// atomically (temporary name + rename).
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/npy.h"

namespace motionpipe {

class Npz {
 public:
  // Adds or replaces the array called `name` (without ".npy").
  void Add(const std::string& name, NpyArray array);
  // nullptr when absent.
  const NpyArray* Find(const std::string& name) const;
  // NotFound naming `origin`, the missing array and the ones present.
  Result<const NpyArray*> Get(const std::string& name, const std::string& origin) const;
  const std::vector<std::pair<std::string, NpyArray>>& arrays() const { return arrays_; }
  // Moves the array out (an empty array stays behind); nullopt when absent.
  std::optional<NpyArray> Take(const std::string& name);

 private:
  std::vector<std::pair<std::string, NpyArray>> arrays_;
};

// `arrays` names the arrays to load (without ".npy"); empty loads all. Arrays not loaded are
// never inflated, so reading a few small arrays of a large archive is cheap.
Result<Npz> ParseNpz(std::string_view bytes, const std::string& origin,
                     const std::vector<std::string>& arrays = {});
std::string SerializeNpz(const Npz& npz, bool compress);
Result<Npz> ReadNpz(const std::string& path, const std::vector<std::string>& arrays = {});
Status WriteNpz(const std::string& path, const Npz& npz, bool compress = true);

// Typed accessors with shape checks, for readers of our layouts. `dims` uses -1 for "any".
// The error names `origin`, the array and the expected and found shapes.
Result<const NpyArray*> GetShaped(const Npz& npz, const std::string& name,
                                  const std::vector<int64_t>& dims, const std::string& origin);

}  // namespace motionpipe
