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

// Atomically replaces `path` with `bytes` (temporary name + fsync + rename). Creates no directories.
// `sync` = false skips the fsync for bulk outputs (the rename still hides partial files).
Status WriteFileAtomic(const std::string& path, std::string_view bytes, bool sync = true);

// Creates `path` and its parents when missing.
Status MakeDirs(const std::string& path);

// Lower-case hex SHA-256 of `bytes` (for output manifests).
std::string Sha256Hex(std::string_view bytes);

}  // namespace motionpipe
