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

// An exclusive lock on a file, held until destruction (LevelDB's LOCK file): flock(2) on `path`
// (created when missing), with the holder's pid written into it. The kernel drops the lock when the
// holder dies, so a crashed process never leaves it held. Move-only.
class FileLock {
 public:
  // FailedPrecondition naming `path` and the holder's pid when another process holds it.
  static Result<FileLock> Acquire(const std::string& path);
  FileLock(FileLock&& other) noexcept;
  FileLock& operator=(FileLock&& other) noexcept;
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;
  ~FileLock();

 private:
  FileLock() = default;
  int fd_ = -1;
};

// Atomically replaces `path` with `bytes` (temporary name + fsync + rename). Creates no
// directories. `sync` = false skips the fsync for bulk outputs (the rename still hides partial
// files).
Status WriteFileAtomic(const std::string& path, std::string_view bytes, bool sync = true);

// fsync(2)s every regular file and directory under `dir` (each directory after its contents) and
// `dir` itself: what a task wrote reaches the disk before its commit is journaled. A missing `dir`
// is OK (nothing to sync). IoError naming the file on the first failure.
Status SyncTree(const std::string& dir);

// fsync(2)s one directory, so that the entries created, renamed or removed in it survive a crash.
Status SyncDir(const std::string& dir);

// Creates `path` and its parents when missing.
Status MakeDirs(const std::string& path);

// MakeDirs, and each directory it creates has its entry fsynced in its parent, so that the new
// directories survive a power loss (LevelDB syncs a new directory's parent the same way).
Status MakeDirsDurable(const std::string& path);

// Lower-case hex SHA-256 of `bytes` (for output manifests).
std::string Sha256Hex(std::string_view bytes);

}  // namespace motionpipe
