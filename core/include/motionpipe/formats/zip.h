// The subset of ZIP that numpy's savez/savez_compressed produce and read: stored and deflated
// members, optional data descriptors, ZIP64 for members or archives past 4 GiB. CRC-32 is checked.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe {

struct ZipMember {
  std::string name;
  std::string data;  // uncompressed
};

// A member located in an archive held in memory, not yet extracted.
struct ZipEntry {
  std::string name;
  uint16_t method = 0;  // 0 stored, 8 deflated
  uint32_t crc = 0;
  uint64_t size = 0;         // uncompressed
  std::string_view payload;  // the stored or deflated bytes, inside the archive
};

// The archive's directory, every entry checked for consistency (nothing is inflated).
Result<std::vector<ZipEntry>> ListZip(std::string_view archive, const std::string& origin);
// Inflates (or copies) one member and checks its CRC.
Result<std::string> ExtractZipEntry(const ZipEntry& entry, const std::string& origin);
// Checks the CRC of a member's uncompressed bytes (a stored member used in place).
Status CheckZipCrc(const ZipEntry& entry, std::string_view data, const std::string& origin);

// Chooses members by name; an empty filter takes all.
using MemberFilter = std::function<bool(const std::string& name)>;

// The members of an archive held in memory, in directory order. The whole directory is checked;
// only the members `want` accepts are inflated (in parallel, OpenMP). DataLoss names `origin` and
// the damaged part.
Result<std::vector<ZipMember>> ReadZip(std::string_view archive, const std::string& origin,
                                       const MemberFilter& want = {});

// Builds an archive in memory. Members are compressed in Finish(), in parallel (OpenMP), each on
// its own, so the bytes do not depend on the thread count. Stored members' data start on 64-byte
// boundaries (padding in a local extra field), so a reader can map the file and use arrays in
// place.
class ZipWriter {
 public:
  // `deflate` chooses compression for this member.
  void Add(const std::string& name, std::string data, bool deflate);
  // The finished archive; the writer is empty afterwards.
  std::string Finish();

 private:
  struct Entry {
    std::string name;
    std::string data;  // uncompressed until Finish(), then the stored payload
    bool deflate = false;
    uint32_t crc = 0;
    uint64_t compressed_size = 0;
    uint64_t size = 0;
    uint64_t offset = 0;
    uint16_t method = 0;
  };
  std::vector<Entry> entries_;
};

}  // namespace motionpipe
