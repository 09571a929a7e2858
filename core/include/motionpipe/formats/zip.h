// The subset of ZIP that numpy's savez/savez_compressed produce and read: stored and deflated
// members, optional data descriptors, ZIP64 for members or archives past 4 GiB. CRC-32 is checked.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe {

struct ZipMember {
  std::string name;
  std::string data;  // uncompressed
};

// Every member of an archive held in memory. DataLoss names `origin` and the damaged part.
Result<std::vector<ZipMember>> ReadZip(std::string_view archive, const std::string& origin);

// Builds an archive in memory. Members are compressed in Finish(), in parallel (OpenMP), each on its
// own, so the bytes do not depend on the thread count.
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
