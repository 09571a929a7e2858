// Whole-file I/O with crash-safe writes: data goes to a temporary name in the same directory, is
// fsync'ed, then renamed over the destination, so a reader sees either the old file or the new one.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "motionpipe/base/status.h"

namespace motionpipe {

// Reads the whole file. NotFound when missing, IoError when unreadable.
Result<std::string> ReadFile(const std::string& path);

// A read-only memory map of a whole file (empty files map to an empty view). Move-only.
class MappedFile {
 public:
  static Result<MappedFile> Open(const std::string& path);
  MappedFile(MappedFile&& other) noexcept;
  MappedFile& operator=(MappedFile&& other) noexcept;
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  ~MappedFile();
  std::string_view data() const { return {static_cast<const char*>(address_), size_}; }

 private:
  MappedFile() = default;
  void* address_ = nullptr;
  size_t size_ = 0;
};

// Atomically replaces `path` with `bytes` (temporary name + fsync + rename). Creates no directories.
// `sync` = false skips the fsync for bulk outputs (the rename still hides partial files).
Status WriteFileAtomic(const std::string& path, std::string_view bytes, bool sync = true);

// Creates `path` and its parents when missing.
Status MakeDirs(const std::string& path);

// Lower-case hex SHA-256 of `bytes` (for output manifests).
std::string Sha256Hex(std::string_view bytes);

}  // namespace motionpipe
